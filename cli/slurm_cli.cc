#include "cli/slurm_cli.h"

#include <cstdlib>

#include "base/atomic_file.h"
#include "evaluate/parts.h"

namespace handdb::cli {

namespace fs = std::filesystem;

void SlurmFlags::Add(CLI::App& app) {
  const char* group = "Slurm (docs/cluster.md)";
  app.add_flag(
         "--slurm", enabled, "run on a Slurm cluster: one array task per unit, then a final job")
      ->group(group);
  app.add_option("--partition", options.partition, "Slurm partition (default: the cluster's)")
      ->group(group);
  app.add_option("--max-parallel",
                 options.max_parallel,
                 "at most N array tasks at once (default: no limit)")
      ->check(CLI::PositiveNumber)
      ->group(group);
  app.add_option(
         "--time", options.time_limit, "time limit of each task, Slurm syntax (e.g. 1:00:00)")
      ->group(group);
  app.add_option(
         "--mem", options.mem_per_task, "memory of each task, e.g. 2G (default: the cluster's)")
      ->group(group);
  app.add_option("--cpus-per-task", options.cpus_per_task, "CPUs of each task")
      ->check(CLI::PositiveNumber)
      ->capture_default_str()
      ->group(group);
  app.add_option("--slurm-setup",
                 setup_file,
                 "file of shell lines every job runs first (module load, PATH=...)")
      ->check(CLI::ExistingFile)
      ->group(group);
  app.add_option("--sbatch-arg", options.sbatch_args, "extra sbatch option, verbatim (repeatable)")
      ->allow_extra_args(false)
      ->group(group);
  app.add_flag("--dry-run", dry_run, "write the job scripts and print the sbatch commands only")
      ->group(group);
  app.add_flag("--wait", wait, "wait for the jobs and report the result (exit 1 on a failure)")
      ->group(group);
  app.add_option("--poll", poll_seconds, "seconds between job-state checks with --wait")
      ->check(CLI::Range(0.1, 3600.0))
      ->capture_default_str()
      ->group(group);
}

int TaskThreads() {
  if (const char* c = std::getenv("SLURM_CPUS_PER_TASK")) {
    const int n = std::atoi(c);
    if (n > 0) return n;
  }
  return 1;
}

Result<fs::path> Absolute(const fs::path& p) {
  std::error_code ec;
  fs::path a = fs::absolute(p, ec);
  if (ec) return Status(StatusCode::kIoError, p.string() + ": " + ec.message());
  a = a.lexically_normal();
  if (!a.has_filename() && a.has_parent_path()) a = a.parent_path();  // "db/" -> "db"
  return a;
}

Result<fs::path> SelfExecutable() {
  std::error_code ec;
  fs::path p = fs::read_symlink("/proc/self/exe", ec);
  if (ec) {
    return Status(StatusCode::kIoError,
                  "/proc/self/exe: cannot find the handdb executable: " + ec.message());
  }
  return p;
}

Result<SlurmOptions> OptionsFromFlags(const SlurmFlags& flags) {
  SlurmOptions options = flags.options;
  if (!options.time_limit.empty() && !IsValidSlurmTime(options.time_limit)) {
    return Status(StatusCode::kInvalidArgument,
                  "--time '" + options.time_limit +
                      "': not a Slurm time (M, M:S, H:M:S, D-H, D-H:M or D-H:M:S)");
  }
  if (!flags.setup_file.empty()) {
    auto setup = ReadFileToString(flags.setup_file);
    if (!setup.ok()) return setup.status();
    options.setup = *setup;
  }
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument,
                  "bad Slurm options (--partition, --mem, --sbatch-arg: see above)");
  }
  return options;
}

SlurmArrayLayout SlurmGenerateLayout::Files() const {
  return {slurm_dir, "generate-array.sbatch", "generate-final.sbatch", "final.log", "u"};
}

SlurmArrayJob SlurmGenerateLayout::Job() const {
  SlurmArrayJob job;
  job.layout = Files();
  job.chdir = run_dir;
  job.generated_by = "handdb generate --slurm";
  job.final_job_suffix = "-final";
  job.array_comment =
      "# Array task i renders unit BASE+i with Blender and converts it into its own shard.\n"
      "# Safe to re-run: finished renders and valid shards are kept, so only missing work runs.\n";
  job.final_comment = "writes the manifest and validates the database.";
  job.task_noun = "unit";
  job.final_noun = "finalize";
  job.array_variables = {{"HANDDB", {handdb.string()}},
                         {"RUN_DIR", {run_dir.string()}},
                         {"DB_DIR", {db_dir.string()}},
                         {"RENDER_ARGS", render_args, true},
                         {"CONVERT_ARGS", convert_args, true}};
  job.final_variables = {{"HANDDB", {handdb.string()}},
                         {"RUN_DIR", {run_dir.string()}},
                         {"DB_DIR", {db_dir.string()}},
                         {"CONVERT_ARGS", convert_args, true}};
  job.task_commands = {
      {R"("$HANDDB" unit render "$RUN_DIR/plan.json" --unit "$task" --out "$RUN_DIR" --quiet )"
       R"("${RENDER_ARGS[@]}")",
       "handdb unit render"},
      {R"("$HANDDB" unit convert "$RUN_DIR" --unit "$task" --out "$DB_DIR" --quiet )"
       R"("${CONVERT_ARGS[@]}")",
       "handdb unit convert"}};
  job.final_command =
      R"("$HANDDB" unit finalize "$RUN_DIR" --out "$DB_DIR" --quiet "${CONVERT_ARGS[@]}")";
  if (build_index) {
    job.final_comment = "writes the manifest, validates the database and builds its index.";
    job.final_command += " --index";
  }
  return job;
}

SlurmArrayLayout SlurmEvaluateLayout::Files() const {
  return {work_dir, "evaluate-array.sbatch", "evaluate-merge.sbatch", "merge.log", kPartPrefix};
}

SlurmArrayJob SlurmEvaluateLayout::Job() const {
  SlurmArrayJob job;
  job.layout = Files();
  job.chdir = submit_dir;
  job.generated_by = "handdb evaluate --slurm";
  job.array_job_suffix = "-eval";
  job.final_job_suffix = "-eval-merge";
  job.array_comment =
      "# Array task i scores slice BASE+i of the test views and writes parts/part-<BASE+i>.json.\n"
      "# Safe to re-run: a complete part of the same evaluation is kept.\n";
  job.final_comment = "merges the parts into the report (text in " +
                      report_text().filename().string() + ", JSON, plots).";
  job.task_noun = "task";
  job.final_noun = "merge";
  job.array_variables = {{"HANDDB", {handdb.string()}}, {"TASK_ARGS", task_args, true}};
  job.final_variables = {{"HANDDB", {handdb.string()}}, {"MERGE_ARGS", merge_args, true}};
  job.task_commands = {
      {R"("$HANDDB" "${TASK_ARGS[@]}" --task "$task" --quiet)", "handdb unit evaluate"}};
  job.final_command = R"("$HANDDB" "${MERGE_ARGS[@]}" --quiet)";
  return job;
}

}  // namespace handdb::cli
