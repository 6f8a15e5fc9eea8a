// What the two Slurm front ends share: `handdb generate --slurm` (cli/slurm_commands.cc) and
// `handdb evaluate --slurm` (cli/evaluate_slurm_commands.cc), and their `handdb unit ...` tasks:
// the --slurm flags, and the job each front end describes to cluster/ (its file names and task
// command lines). cluster/ does the rest (scripts, submission, waiting, failure reports), so the
// two commands' messages and failure reports stay alike.
#pragma once

#include <CLI/CLI.hpp>
#include <filesystem>
#include <string>
#include <vector>

#include "base/status.h"
#include "cluster/slurm.h"

namespace handdb::cli {

// The --slurm options of a command that can run as a Slurm job array; the Slurm options are
// bound to `options`' fields.
struct SlurmFlags {
  bool enabled = false;
  SlurmOptions options;
  bool dry_run = false;
  bool wait = false;
  double poll_seconds = 10;
  std::filesystem::path setup_file;
  void Add(CLI::App& app);
};

// Threads for a task: what Slurm gave it ($SLURM_CPUS_PER_TASK), else 1.
int TaskThreads();

// `p` absolute and normalised, without a trailing separator ("db/" -> "/abs/db").
Result<std::filesystem::path> Absolute(const std::filesystem::path& p);

// The running handdb executable (what the jobs run on the shared filesystem).
Result<std::filesystem::path> SelfExecutable();

// The SlurmOptions of --partition, --time, --mem, ... with --time and --slurm-setup checked.
Result<SlurmOptions> OptionsFromFlags(const SlurmFlags& flags);

// Where `handdb generate --slurm` keeps its files and what its jobs run. All paths absolute.
struct SlurmGenerateLayout {
  std::filesystem::path handdb;     // the handdb executable the jobs run (shared filesystem)
  std::filesystem::path run_dir;    // RUN_DIR: plan.json, units/
  std::filesystem::path db_dir;     // DB_DIR: shards, manifest
  std::filesystem::path slurm_dir;  // scripts, logs, failure markers, jobs.json
  // Extra arguments, passed verbatim: to `handdb unit render` (e.g. --blender PATH) and to
  // `handdb unit convert` / `unit finalize` (edge options, --skip-bad, as typed), so every task
  // converts exactly as a local `handdb generate` with the same options would.
  std::vector<std::string> render_args;
  std::vector<std::string> convert_args;
  // `handdb generate --index`: the final job also builds the search index (`unit finalize
  // --index`: `handdb index DB`'s work with its defaults, on the job's CPUs) once it validates.
  bool build_index = false;

  // slurm/generate-array.sbatch, generate-final.sbatch, logs/u00007.log, logs/final.log, ...
  SlurmArrayLayout Files() const;
  // Each array task renders its unit (`handdb unit render`) and converts it (`handdb unit
  // convert`), both no-ops when already done; the final job runs `handdb unit finalize`
  // (manifest + validation).
  SlurmArrayJob Job() const;
};

// Where `handdb evaluate --slurm` keeps its files (WORK = the evaluation's work directory).
struct SlurmEvaluateLayout {
  std::filesystem::path handdb;      // the handdb executable the jobs run (shared filesystem)
  std::filesystem::path submit_dir;  // every job runs here (--chdir): the DB, test-set, --json and
                                     // --plots paths resolve as they did when submitted
  std::filesystem::path work_dir;    // WORK: parts/, logs/, failed/, scripts, jobs.json
  // The words after `handdb` each array task runs (the script appends --task T) and the final job
  // runs: `unit evaluate DB TESTSET --tasks N --work WORK OPTIONS...` and
  // `unit evaluate-merge DB TESTSET --tasks N --work WORK OPTIONS... [--json F] [--plots P]`.
  std::vector<std::string> task_args;
  std::vector<std::string> merge_args;

  // WORK/evaluate-array.sbatch, evaluate-merge.sbatch, logs/part-00007.log (the part's name),
  // logs/merge.log, ...
  SlurmArrayLayout Files() const;
  std::filesystem::path report_text() const { return work_dir / "report.txt"; }
  // Task T runs `handdb unit evaluate ... --task T` (a no-op when its part is already complete);
  // the final job `handdb unit evaluate-merge ...` (report text, JSON, plots).
  SlurmArrayJob Job() const;
};

}  // namespace handdb::cli
