#include "cluster/slurm.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "base/atomic_file.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

class TempDir {
 public:
  TempDir() {
    path_ = fs::temp_directory_path() /
            ("handdb-slurm-test-" + std::to_string(getpid()) + "-" + std::to_string(counter_++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  static inline int counter_ = 0;
  fs::path path_;
};

std::string Slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A stand-in for handdb in `dir`: prints its arguments as [a][b]... and exits with $RC (0 unset).
fs::path EchoArgsProgram(const fs::path& dir) {
  const fs::path path = dir / "echo-args";
  EXPECT_TRUE(WriteFileAtomic(path, "#!/bin/sh\nprintf '[%s]' \"$@\"; echo; exit ${RC:-0}\n").ok());
  fs::permissions(path, fs::perms::owner_all);
  return path;
}

// Runs array script `script` with argument `base` (the chunk's base) as Slurm runs task `task` of
// array job `job`, with extra environment `env` ("NAME=VALUE"). Returns the exit code (-1: no run).
int RunArrayTask(const fs::path& script,
                 const std::string& job,
                 const std::string& base,
                 const std::string& task,
                 const std::vector<std::string>& env = {}) {
  std::vector<std::string> argv = {"env"};
  argv.insert(argv.end(), env.begin(), env.end());
  argv.insert(
      argv.end(),
      {"SLURM_ARRAY_JOB_ID=" + job, "SLURM_ARRAY_TASK_ID=" + task, "bash", script.string(), base});
  auto r = RunCommand(argv);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  return r.ok() ? r->exit_code : -1;
}

TEST(Slurm, FormatArrayRanges) {
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{}), "");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{5}), "5");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{0, 1, 2, 3}), "0-3");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{0, 1, 2, 3, 7, 9, 10, 11, 12}), "0-3,7,9-12");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{1, 3, 5}), "1,3,5");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{4, 5}), "4-5");
}

TEST(Slurm, ArraySpecAddsThrottle) {
  ArrayChunk chunk{0, {0, 1, 2, 6}};
  EXPECT_EQ(chunk.ArraySpec(0), "0-2,6");
  EXPECT_EQ(chunk.ArraySpec(4), "0-2,6%4");
}

TEST(Slurm, PlanArrayChunksSmallPlanIsOneChunkWithUnitIds) {
  const auto chunks = PlanArrayChunks({7, 1, 2, 2, 3}, 1001);
  ASSERT_EQ(chunks.size(), 1u);
  EXPECT_EQ(chunks[0].base, 0u);
  EXPECT_EQ(chunks[0].indices, (std::vector<uint32_t>{1, 2, 3, 7}));
  EXPECT_TRUE(PlanArrayChunks({}, 1001).empty());
}

TEST(Slurm, PlanArrayChunksKeepsIndicesBelowMaxArraySize) {
  // MaxArraySize 10: indices 0..9 only; unit 25 -> base 20, index 5.
  const auto chunks = PlanArrayChunks({0, 9, 10, 11, 25, 9}, 10);
  ASSERT_EQ(chunks.size(), 3u);
  EXPECT_EQ(chunks[0].base, 0u);
  EXPECT_EQ(chunks[0].indices, (std::vector<uint32_t>{0, 9}));
  EXPECT_EQ(chunks[1].base, 10u);
  EXPECT_EQ(chunks[1].indices, (std::vector<uint32_t>{0, 1}));
  EXPECT_EQ(chunks[2].base, 20u);
  EXPECT_EQ(chunks[2].indices, (std::vector<uint32_t>{5}));
  for (const auto& c : chunks) {
    for (uint32_t i : c.indices) EXPECT_LT(i, 10u);
  }
}

TEST(Slurm, PendingUnitsAreTheIncompleteOnes) {
  const std::vector<bool> complete = {true, false, true, true, false, false};
  const auto pending = PendingUnits(6, [&](uint32_t u) { return complete[u]; });
  EXPECT_EQ(pending, (std::vector<uint32_t>{1, 4, 5}));
  EXPECT_EQ(FormatArrayRanges(pending), "1,4-5");
  EXPECT_TRUE(PendingUnits(3, [](uint32_t) { return true; }).empty());
}

TEST(Slurm, SlurmTimeFormats) {
  for (const char* t : {"30", "30:00", "1:00:00", "2-0", "2-12:00", "2-12:00:00", "UNLIMITED"}) {
    EXPECT_TRUE(IsValidSlurmTime(t)) << t;
  }
  for (const char* t : {"", "1h", "1:00:00:00", "-5", "1-", "a:b", "1 :00"}) {
    EXPECT_FALSE(IsValidSlurmTime(t)) << t;
  }
}

TEST(Slurm, OptionsCheck) {
  SlurmOptions ok;
  ok.partition = "gpu-short";
  ok.time_limit = "0:30:00";
  ok.max_parallel = 8;
  ok.mem_per_task = "2G";
  ok.sbatch_args = {"--account=hands"};
  EXPECT_TRUE(ok.Check());

  SlurmOptions bad_time = ok;
  bad_time.time_limit = "half an hour";
  EXPECT_FALSE(bad_time.Check());
  SlurmOptions bad_partition = ok;
  bad_partition.partition = "a b";
  EXPECT_FALSE(bad_partition.Check());
  SlurmOptions bad_parallel = ok;
  bad_parallel.max_parallel = -1;
  EXPECT_FALSE(bad_parallel.Check());
  SlurmOptions bad_arg = ok;
  bad_arg.sbatch_args = {"account=hands"};
  EXPECT_FALSE(bad_arg.Check());
  SlurmOptions bad_mem = ok;
  bad_mem.mem_per_task = "lots";
  EXPECT_FALSE(bad_mem.Check());
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
  const std::string s = GenerateArrayScript(layout, options);
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
  EXPECT_EQ(GenerateArrayScript(layout, plain).find("--partition"), std::string::npos);
  EXPECT_EQ(GenerateArrayScript(layout, plain).find("--time"), std::string::npos);
}

TEST(Slurm, FinalScriptText) {
  SlurmOptions options;
  options.partition = "short";
  const auto layout = LayoutIn("/shared/x", "/opt/handdb/bin/handdb");
  const std::string s = GenerateFinalScript(layout, options);
  EXPECT_NE(s.find("#SBATCH --job-name=handdb-final\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --partition=short\n"), std::string::npos);
  EXPECT_NE(s.find("#SBATCH --output=/shared/x/run dir/slurm/logs/final.log\n"), std::string::npos);
  EXPECT_NE(s.find("unit finalize \"$RUN_DIR\" --out \"$DB_DIR\""), std::string::npos);
}

TEST(Slurm, ShellQuote) {
  EXPECT_EQ(ShellQuote("abc"), "'abc'");
  EXPECT_EQ(ShellQuote("it's"), "'it'\\''s'");
  EXPECT_EQ(FormatCommand({"sbatch", "--array=0-3%2", "/a b/c"}), "sbatch --array=0-3%2 '/a b/c'");
}

TEST(Slurm, RunCommandCapturesOutputAndExitCode) {
  auto ok = RunCommand({"sh", "-c", "echo out; echo err >&2; exit 3"});
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(ok->out, "out\n");
  EXPECT_EQ(ok->err, "err\n");
  EXPECT_EQ(ok->exit_code, 3);
  auto missing = RunCommand({"handdb-no-such-program-xyz"});
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kExternalToolFailed);
  EXPECT_NE(missing.status().message().find("handdb-no-such-program-xyz"), std::string::npos);
}

// Runs the generated array script as Slurm would run array task `task` of job 99, with `handdb`
// replaced by a real program (/bin/true or /bin/false), and checks the failure bookkeeping.
TEST(Slurm, ArrayScriptRecordsFailureAndClearsItOnSuccess) {
  TempDir tmp;
  SlurmOptions options;
  options.setup = "echo setup-ran";
  auto layout = LayoutIn(tmp.path(), "/bin/false");
  auto dry = SubmitGenerateJobs(layout, options, {7}, /*dry_run=*/true);
  ASSERT_TRUE(dry.ok()) << dry.status().ToString();
  auto run_task = [&](const std::string& base, const std::string& task) {
    return RunArrayTask(layout.array_script(), "99", base, task);
  };
  // Base 5 + task 2 = unit 7.
  EXPECT_EQ(run_task("5", "2"), 1);
  ASSERT_TRUE(fs::exists(layout.UnitFailedMarker(7)));
  EXPECT_NE(Slurp(layout.UnitFailedMarker(7)).find("exit code 1 from handdb unit render"),
            std::string::npos);
  EXPECT_NE(Slurp(layout.UnitFailedMarker(7)).find("Slurm task 99_2"), std::string::npos);
  const std::string log = Slurp(layout.UnitLog(7));
  EXPECT_NE(log.find("=== unit 7: Slurm task 99_2"), std::string::npos);
  EXPECT_NE(log.find("setup-ran"), std::string::npos);
  EXPECT_NE(log.find("unit 7 failed"), std::string::npos);

  // The re-run succeeds: the marker goes away, the log keeps both attempts.
  layout.handdb = "/bin/true";
  ASSERT_TRUE(SubmitGenerateJobs(layout, options, {7}, true).ok());
  EXPECT_EQ(run_task("0", "7"), 0);
  EXPECT_FALSE(fs::exists(layout.UnitFailedMarker(7)));
  const std::string log2 = Slurp(layout.UnitLog(7));
  EXPECT_NE(log2.find("unit 7 failed"), std::string::npos);
  EXPECT_NE(log2.find("=== unit 7: done"), std::string::npos);
}

// The per-task commands get the render and convert arguments as separate words, spaces kept.
TEST(Slurm, ArrayScriptPassesArgumentsVerbatim) {
  TempDir tmp;
  auto layout = LayoutIn(tmp.path(), EchoArgsProgram(tmp.path()));
  layout.render_args = {"--blender", "/opt/my blender/blender"};
  layout.convert_args = {"--occlusion-edges", "off", "--skip-bad"};
  ASSERT_TRUE(SubmitGenerateJobs(layout, SlurmOptions{}, {3}, true).ok());
  ASSERT_EQ(RunArrayTask(layout.array_script(), "5", "0", "3"), 0);
  const std::string log = Slurp(layout.UnitLog(3));
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
  auto r = RunCommand({"env", "SLURM_JOB_ID=6", "bash", layout.final_script().string()});
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
  for (const auto& d : {layout.submit_dir, layout.log_dir(), layout.failed_dir()}) {
    fs::create_directories(d);
  }
  SlurmOptions options;
  options.partition = "short";
  ASSERT_TRUE(WriteFileAtomic(layout.array_script(), EvaluateArrayScript(layout, options)).ok());
  ASSERT_TRUE(WriteFileAtomic(layout.final_script(), EvaluateFinalScript(layout, options)).ok());
  const std::string array = Slurp(layout.array_script());
  EXPECT_NE(array.find("#SBATCH --chdir=" + layout.submit_dir.string() + "\n"), std::string::npos);
  EXPECT_NE(array.find("#SBATCH --partition=short\n"), std::string::npos);
  EXPECT_NE(array.find("#SBATCH --job-name=handdb-eval\n"), std::string::npos);

  auto run_task = [&](const std::string& base, const std::string& task, const std::string& rc) {
    return RunArrayTask(layout.array_script(), "8", base, task, {"RC=" + rc});
  };
  // Base 1 + task 1 = task 2.
  EXPECT_EQ(run_task("1", "1", "3"), 1);
  ASSERT_TRUE(fs::exists(layout.TaskFailedMarker(2)));
  EXPECT_EQ(layout.TaskFailedMarker(2).filename(), "part-00002");
  EXPECT_NE(Slurp(layout.TaskFailedMarker(2)).find("exit code 3 from handdb unit evaluate"),
            std::string::npos);
  EXPECT_EQ(run_task("0", "2", "0"), 0);
  EXPECT_FALSE(fs::exists(layout.TaskFailedMarker(2)));
  const std::string log = Slurp(layout.TaskLog(2));
  EXPECT_EQ(layout.TaskLog(2).filename(), "part-00002.log");
  EXPECT_NE(log.find("[unit][evaluate][db dir][ts][--tasks][3][--task][2][--quiet]\n"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("=== task 2: done"), std::string::npos) << log;

  auto r = RunCommand({"env", "SLURM_JOB_ID=9", "bash", layout.final_script().string()});
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
  auto sub = SubmitGenerateJobs(layout, options, {0, 1, 2, 5, 6}, /*dry_run=*/true);
  ASSERT_TRUE(sub.ok()) << sub.status().ToString();
  EXPECT_TRUE(fs::exists(layout.array_script()));
  EXPECT_TRUE(fs::exists(layout.final_script()));
  EXPECT_FALSE(fs::exists(layout.jobs_file()));
  EXPECT_TRUE(sub->array_job_ids.empty());
  ASSERT_EQ(sub->sbatch_commands.size(), 3u);  // two chunks (bases 0 and 4) + final
  EXPECT_EQ(
      FormatCommand(sub->sbatch_commands[0]),
      "sbatch --parsable --array=0-2%2 " + FormatCommand({layout.array_script().string()}) + " 0");
  EXPECT_EQ(sub->sbatch_commands[1][2], "--array=1-2%2");
  EXPECT_EQ(sub->sbatch_commands[1].back(), "4");
  EXPECT_EQ(sub->sbatch_commands[2][2], "--dependency=afterok:ARRAY_JOB_ID:ARRAY_JOB_ID");
  // The scripts are valid bash.
  for (const auto& script : {layout.array_script(), layout.final_script()}) {
    auto r = RunCommand({"bash", "-n", script.string()});
    ASSERT_TRUE(r.ok());
    EXPECT_EQ(r->exit_code, 0) << r->err;
  }
}

TEST(Slurm, ParseScontrolJobs) {
  const std::string text =
      "JobId=8 ArrayJobId=5 ArrayTaskId=1 JobName=wrap UserId=root(0) JobState=FAILED "
      "Reason=NonZeroExitCode Dependency=(null) ExitCode=3:0 StdOut=/tmp/f-1.txt Power=\n"
      "JobId=5 ArrayJobId=5 ArrayTaskId=2-3 JobName=wrap JobState=PENDING Reason=None "
      "ExitCode=0:0\n"
      "JobId=6 JobName=final JobState=CANCELLED Reason=DependencyNeverSatisfied ExitCode=0:0\n";
  const auto jobs = ParseScontrolJobs(text);
  ASSERT_EQ(jobs.size(), 3u);
  EXPECT_EQ(jobs[0].job_id, "8");
  EXPECT_EQ(jobs[0].array_job_id, "5");
  EXPECT_EQ(jobs[0].array_task_id, 1);
  EXPECT_EQ(jobs[0].state, "FAILED");
  EXPECT_EQ(jobs[0].exit_code, "3:0");
  EXPECT_EQ(jobs[0].std_out, "/tmp/f-1.txt");
  EXPECT_EQ(jobs[1].array_task_id, -1);  // a pending range, not one task
  EXPECT_EQ(jobs[1].state, "PENDING");
  EXPECT_EQ(jobs[2].array_job_id, "");
  EXPECT_EQ(jobs[2].reason, "DependencyNeverSatisfied");
  EXPECT_TRUE(IsFinishedJobState("CANCELLED"));
  EXPECT_TRUE(IsFinishedJobState("TIMEOUT"));
  EXPECT_FALSE(IsFinishedJobState("PENDING"));
  EXPECT_FALSE(IsFinishedJobState("COMPLETING"));
}

TEST(Slurm, SubmissionRecordRoundTrip) {
  TempDir tmp;
  SlurmSubmission sub;
  sub.array_job_ids = {"12", "13"};
  sub.chunk_bases = {0, 1001};
  sub.final_job_id = "14";
  sub.db_dir = "/shared/db";
  sub.units = {1, 2, 1003};
  sub.sbatch_commands = {{"sbatch", "--parsable", "x"}};
  ASSERT_TRUE(WriteSubmissionRecord(tmp.path() / "jobs.json", sub).ok());
  auto back = ReadSubmissionRecord(tmp.path() / "jobs.json");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->array_job_ids, sub.array_job_ids);
  EXPECT_EQ(back->chunk_bases, sub.chunk_bases);
  EXPECT_EQ(back->final_job_id, "14");
  EXPECT_EQ(back->db_dir, "/shared/db");
  EXPECT_EQ(back->units, sub.units);
  ASSERT_TRUE(WriteFileAtomic(tmp.path() / "bad.json", "{\"format\": \"x\"}").ok());
  auto bad = ReadSubmissionRecord(tmp.path() / "bad.json");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("bad.json"), std::string::npos);
}

TEST(Slurm, FormatUnitFailure) {
  EXPECT_EQ(FormatUnitFailure({3, "TIMEOUT", "/r/slurm/logs/u00003.log"}),
            "unit 3: TIMEOUT; log: /r/slurm/logs/u00003.log");
}

}  // namespace
}  // namespace handdb
