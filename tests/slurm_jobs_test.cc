// The job scripts `handdb generate --slurm` and `handdb evaluate --slurm` describe to cluster/
// (cli/slurm_cli.h): their text, and what their tasks run when bash runs them as Slurm would.
#include <gtest/gtest.h>

#include <filesystem>

#include "base/atomic_file.h"
#include "cli/slurm_cli.h"
#include "cluster/slurm.h"
#include "cluster/slurm_testing.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using testing::EchoArgsProgram;
using testing::RunArrayTask;
using testing::Slurp;
using testing::TempDir;

// What `handdb generate --slurm` does with its layout: write both scripts, then submit (or not).
Result<SlurmSubmission> WriteAndSubmit(const SlurmGenerateLayout& layout,
                                       const SlurmOptions& options,
                                       const std::vector<uint32_t>& units,
                                       bool dry_run) {
  HANDDB_RETURN_IF_ERROR(WriteJobScripts(layout.Job(), options));
  return SubmitArrayWithFinal(layout.Files(), layout.db_dir.string(), options, units, dry_run);
}

SlurmGenerateLayout LayoutIn(const fs::path& root, const fs::path& handdb) {
  SlurmGenerateLayout layout;
  layout.handdb = handdb;
  layout.run_dir = root / "run dir";  // a space, to prove the quoting
  layout.db_dir = root / "db";
  layout.slurm_dir = layout.run_dir / "slurm";
  return layout;
}

TEST(Slurm, ArrayScriptText) {
  SlurmOptions options;
  options.partition = "short";
  options.time_limit = "1:00:00";
  options.mem_per_task = "3G";
  options.sbatch_args = {"--account=hands"};
  options.setup = "module load blender/3.4";
  const auto layout = LayoutIn("/shared/x", "/opt/handdb/bin/handdb");
  const std::string s = ArrayScript(layout.Job(), options);
  EXPECT_EQ(s.rfind("#!/bin/bash\n", 0), 0u);
  EXPECT_NE(s.find("#SBATCH --job-name=handdb\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --partition=short\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --time=1:00:00\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --mem=3G\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --cpus-per-task=1\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --account=hands\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --output=/shared/x/run dir/slurm/logs/slurm-%A_%a.out\n"),
            std::string::npos);
  EXPECT_NE(s.find("RUN_DIR='/shared/x/run dir'\n"), std::string::npos);
  EXPECT_NE(s.find("HANDDB='/opt/handdb/bin/handdb'\n"), std::string::npos);
  EXPECT_NE(s.find("module load blender/3.4\n"), std::string::npos);
  EXPECT_NE(s.find("unit render"), std::string::npos);
  EXPECT_NE(s.find("unit convert"), std::string::npos);
  // Setup runs before the first handdb command; no partition line when none is given.
  EXPECT_LT(s.find("module load"), s.find("unit render"));
  SlurmOptions plain;
  EXPECT_EQ(ArrayScript(layout.Job(), plain).find("--partition"), std::string::npos);
  EXPECT_EQ(ArrayScript(layout.Job(), plain).find("--time"), std::string::npos);
}

TEST(Slurm, FinalScriptText) {
  SlurmOptions options;
  options.partition = "short";
  const auto layout = LayoutIn("/shared/x", "/opt/handdb/bin/handdb");
  const std::string s = FinalScript(layout.Job(), options);
  EXPECT_NE(s.find("#SBATCH --job-name=handdb-final\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --partition=short\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --output=/shared/x/run dir/slurm/logs/final.log\n"), std::string::npos);
  EXPECT_NE(s.find("unit finalize \"$RUN_DIR\" --out \"$DB_DIR\""), std::string::npos);
}

// Runs the generated array script as Slurm would run array task `task` of job 99, with `handdb`
// replaced by a real program (/bin/true or /bin/false), and checks the failure bookkeeping.
TEST(Slurm, ArrayScriptRecordsFailureAndClearsItOnSuccess) {
  TempDir tmp;
  SlurmOptions options;
  options.setup = "echo setup-ran";
  auto layout = LayoutIn(tmp.path(), "/bin/false");
  auto dry = WriteAndSubmit(layout, options, {7}, /*dry_run=*/true);
  ASSERT_TRUE(dry.ok()) << dry.status().ToString();
  auto run_task = [&](const std::string& base, const std::string& task) {
    return RunArrayTask(layout.Files().array_script(), "99", base, task);
  };
  // Base 5 + task 2 = unit 7.
  EXPECT_EQ(run_task("5", "2"), 1);
  ASSERT_TRUE(fs::exists(layout.Files().TaskFailedMarker(7)));
  EXPECT_NE(Slurp(layout.Files().TaskFailedMarker(7)).find("exit code 1 from handdb unit render"),
            std::string::npos);
  EXPECT_NE(Slurp(layout.Files().TaskFailedMarker(7)).find("Slurm task 99_2"), std::string::npos);
  const std::string log = Slurp(layout.Files().TaskLog(7));
  EXPECT_NE(log.find("=== unit 7: Slurm task 99_2"), std::string::npos);
  EXPECT_NE(log.find("setup-ran"), std::string::npos);
  EXPECT_NE(log.find("unit 7 failed"), std::string::npos);

  // The re-run succeeds: the marker goes away, the log keeps both attempts.
  layout.handdb = "/bin/true";
  ASSERT_TRUE(WriteAndSubmit(layout, options, {7}, true).ok());
  EXPECT_EQ(run_task("0", "7"), 0);
  EXPECT_FALSE(fs::exists(layout.Files().TaskFailedMarker(7)));
  const std::string log2 = Slurp(layout.Files().TaskLog(7));
  EXPECT_NE(log2.find("unit 7 failed"), std::string::npos);
  EXPECT_NE(log2.find("=== unit 7: done"), std::string::npos);
}

// The per-task commands get the render and convert arguments as separate words, spaces kept.
TEST(Slurm, ArrayScriptPassesArgumentsVerbatim) {
  TempDir tmp;
  auto layout = LayoutIn(tmp.path(), EchoArgsProgram(tmp.path()));
  layout.render_args = {"--blender", "/opt/my blender/blender"};
  layout.convert_args = {"--occlusion-edges", "off", "--skip-bad"};
  ASSERT_TRUE(WriteAndSubmit(layout, SlurmOptions{}, {3}, true).ok());
  ASSERT_EQ(RunArrayTask(layout.Files().array_script(), "5", "0", "3"), 0);
  const std::string log = Slurp(layout.Files().TaskLog(3));
  const std::string run_dir = layout.run_dir.string();
  EXPECT_NE(log.find("[unit][render][" + run_dir + "/plan.json][--unit][3][--out][" + run_dir +
                     "][--quiet][--blender][/opt/my blender/blender]\n"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("[unit][convert][" + run_dir + "][--unit][3][--out][" +
                     layout.db_dir.string() + "][--quiet][--occlusion-edges][off][--skip-bad]\n"),
            std::string::npos)
      << log;
  // The final job passes the convert arguments too.
  auto r = RunCommand({"env", "SLURM_JOB_ID=6", "bash", layout.Files().final_script().string()});
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->exit_code, 0);
  EXPECT_NE(r->out.find("[unit][finalize][" + run_dir + "][--out][" + layout.db_dir.string() +
                        "][--quiet][--occlusion-edges][off][--skip-bad]\n"),
            std::string::npos)
      << r->out;
}

// `handdb evaluate --slurm`: task BASE+i runs the task words + --task, in the submission
// directory; a failure leaves a marker naming the task; the merge job runs the merge words.
TEST(Slurm, EvaluateScriptsRunTaskAndMergeWords) {
  TempDir tmp;
  SlurmEvaluateLayout layout;
  layout.handdb = EchoArgsProgram(tmp.path());
  layout.submit_dir = tmp.path() / "my cwd";
  layout.work_dir = tmp.path() / "work";
  layout.task_args = {"unit", "evaluate", "db dir", "ts", "--tasks", "3"};
  layout.merge_args = {
      "unit", "evaluate-merge", "db dir", "ts", "--tasks", "3", "--json", "r.json"};
  for (const auto& d : {layout.submit_dir, layout.Files().log_dir(), layout.Files().failed_dir()}) {
    fs::create_directories(d);
  }
  SlurmOptions options;
  options.partition = "short";
  ASSERT_TRUE(
      WriteFileAtomic(layout.Files().array_script(), ArrayScript(layout.Job(), options)).ok());
  ASSERT_TRUE(
      WriteFileAtomic(layout.Files().final_script(), FinalScript(layout.Job(), options)).ok());
  const std::string array = Slurp(layout.Files().array_script());
  EXPECT_NE(array.find("#SBATCH --chdir=" + layout.submit_dir.string() + "\n"), std::string::npos);
  EXPECT_NE(array.find("#SBATCH --partition=short\n"), std::string::npos);
  EXPECT_NE(array.find("#SBATCH --job-name=handdb-eval\n"), std::string::npos);

  auto run_task = [&](const std::string& base, const std::string& task, const std::string& rc) {
    return RunArrayTask(layout.Files().array_script(), "8", base, task, {"RC=" + rc});
  };
  // Base 1 + task 1 = task 2.
  EXPECT_EQ(run_task("1", "1", "3"), 1);
  ASSERT_TRUE(fs::exists(layout.Files().TaskFailedMarker(2)));
  EXPECT_EQ(layout.Files().TaskFailedMarker(2).filename(), "part-00002");
  EXPECT_NE(Slurp(layout.Files().TaskFailedMarker(2)).find("exit code 3 from handdb unit evaluate"),
            std::string::npos);
  EXPECT_EQ(run_task("0", "2", "0"), 0);
  EXPECT_FALSE(fs::exists(layout.Files().TaskFailedMarker(2)));
  const std::string log = Slurp(layout.Files().TaskLog(2));
  EXPECT_EQ(layout.Files().TaskLog(2).filename(), "part-00002.log");
  EXPECT_NE(log.find("[unit][evaluate][db dir][ts][--tasks][3][--task][2][--quiet]\n"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("=== task 2: done"), std::string::npos) << log;

  auto r = RunCommand({"env", "SLURM_JOB_ID=9", "bash", layout.Files().final_script().string()});
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->exit_code, 0);
  EXPECT_NE(
      r->out.find("[unit][evaluate-merge][db dir][ts][--tasks][3][--json][r.json][--quiet]\n"),
      std::string::npos)
      << r->out;
}

TEST(Slurm, DryRunWritesScriptsAndCommandsWithoutSubmitting) {
  TempDir tmp;
  SlurmOptions options;
  options.max_parallel = 2;
  options.max_array_size = 4;
  const auto layout = LayoutIn(tmp.path(), "/usr/bin/handdb");
  auto sub = WriteAndSubmit(layout, options, {0, 1, 2, 5, 6}, /*dry_run=*/true);
  ASSERT_TRUE(sub.ok()) << sub.status().ToString();
  EXPECT_TRUE(fs::exists(layout.Files().array_script()));
  EXPECT_TRUE(fs::exists(layout.Files().final_script()));
  EXPECT_FALSE(fs::exists(layout.Files().jobs_file()));
  EXPECT_TRUE(sub->array_job_ids.empty());
  ASSERT_EQ(sub->sbatch_commands.size(), 3u);  // two chunks (bases 0 and 4) + final
  EXPECT_EQ(FormatCommand(sub->sbatch_commands[0]),
            "sbatch --parsable --array=0-2%2 " +
                FormatCommand({layout.Files().array_script().string()}) + " 0");
  EXPECT_EQ(sub->sbatch_commands[1][2], "--array=1-2%2");
  EXPECT_EQ(sub->sbatch_commands[1].back(), "4");
  EXPECT_EQ(sub->sbatch_commands[2][2], "--dependency=afterok:ARRAY_JOB_ID:ARRAY_JOB_ID");
  // The scripts are valid bash.
  for (const auto& script : {layout.Files().array_script(), layout.Files().final_script()}) {
    auto r = RunCommand({"bash", "-n", script.string()});
    ASSERT_TRUE(r.ok());
    EXPECT_EQ(r->exit_code, 0) << r->err;
  }
}

}  // namespace
}  // namespace handdb::cli
