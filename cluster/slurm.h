// Scale-out on a real cluster engine: `handdb generate --slurm` as a Slurm job array.
//
// One array task per render unit (render the unit with Blender, convert it into its own shard),
// then one final job, dependent on the array with afterok, that writes the manifest and validates
// the database. Units are the unit of work everywhere (docs/conventions.md), so a database built
// on Slurm is byte-identical to one built locally. Every task is idempotent; a re-run submits only
// the units whose shard is missing or invalid (the array index list is computed from disk).
//
// This file holds the parts that do not depend on a running cluster (the array index list, the
// script text, option checks) and the thin layer that talks to Slurm through its ordinary
// commands (sbatch --parsable, scontrol -o show job), so it works against any Slurm >= 20.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"

namespace handdb {

struct SlurmOptions {
  std::string partition;     // --partition; empty: the cluster's default partition
  int max_parallel = 0;      // at most this many array tasks run at once (%N); 0: no limit
  std::string time_limit;    // --time of each array task, Slurm syntax; empty: default
  int cpus_per_task = 1;     // one Blender process per task is single-threaded (-t 1)
  std::string mem_per_task;  // --mem, e.g. "2G"; empty: the cluster's default
  std::string job_name = "handdb";
  std::vector<std::string> sbatch_args;  // extra sbatch options, verbatim (e.g. "--account=x")
  std::string setup;  // shell lines run first in every job (module load ..., PATH=...)
  // The cluster's MaxArraySize (every array index must be below it); queried from
  // `scontrol show config` when submitting, Slurm's default otherwise.
  uint32_t max_array_size = 1001;
  bool Check() const;
};

// True for the time formats sbatch accepts: M, M:S, H:M:S, D-H, D-H:M, D-H:M:S, or "UNLIMITED".
bool IsValidSlurmTime(const std::string& time);

// "0-3,7,9-12" from sorted unique ids.
std::string FormatArrayRanges(std::span<const uint32_t> sorted_ids);

// One sbatch array submission: array task i handles unit `base + i`, for i in `indices`.
struct ArrayChunk {
  uint32_t base = 0;
  std::vector<uint32_t> indices;  // sorted, unique, each < max_array_size
  // "--array=0-3,7%4" argument (without "--array=").
  std::string ArraySpec(int max_parallel) const;
};

// Splits the units to run into as few array submissions as possible, each keeping every array
// index below `max_array_size` (base = a multiple of max_array_size; a plan with fewer units than
// MaxArraySize is always one chunk with base 0, so array task id == unit id).
std::vector<ArrayChunk> PlanArrayChunks(std::vector<uint32_t> units, uint32_t max_array_size);

// The units in [0, num_units) that are not complete, in increasing order.
template <typename IsComplete>
std::vector<uint32_t> PendingUnits(uint32_t num_units, IsComplete&& is_complete) {
  std::vector<uint32_t> pending;
  for (uint32_t u = 0; u < num_units; ++u) {
    if (!is_complete(u)) pending.push_back(u);
  }
  return pending;
}

// Where a Slurm generation keeps its files. All paths absolute: they are read on compute nodes.
struct SlurmGenerateLayout {
  std::filesystem::path handdb;     // the handdb executable the jobs run (shared filesystem)
  std::filesystem::path run_dir;    // RUN_DIR: plan.json, units/
  std::filesystem::path db_dir;     // DB_DIR: shards, manifest
  std::filesystem::path slurm_dir;  // scripts, logs, failure markers, jobs.json
  // Extra arguments, passed verbatim: to `handdb unit render` (e.g. --blender PATH) and to
  // `handdb unit convert` / `unit finalize` (edge options, --skip-bad), so every task converts
  // exactly as a local `handdb generate` with the same options would.
  std::vector<std::string> render_args;
  std::vector<std::string> convert_args;

  std::filesystem::path array_script() const { return slurm_dir / "generate-array.sbatch"; }
  std::filesystem::path final_script() const { return slurm_dir / "generate-final.sbatch"; }
  std::filesystem::path log_dir() const { return slurm_dir / "logs"; }
  std::filesystem::path failed_dir() const { return slurm_dir / "failed"; }
  std::filesystem::path jobs_file() const { return slurm_dir / "jobs.json"; }
  // The log every attempt at unit `unit` appends to: slurm/logs/u00007.log.
  std::filesystem::path UnitLog(uint32_t unit) const;
  // Written by a task whose unit failed (exit code, job id, host); removed when it succeeds.
  std::filesystem::path UnitFailedMarker(uint32_t unit) const;
  std::filesystem::path final_log() const { return log_dir() / "final.log"; }
};

// The sbatch script of the array: argument $1 is the chunk's base. Each task renders its unit
// (`handdb unit render`), converts it (`handdb unit convert`), both no-ops when already done, and
// records a failure marker with the exit code when either fails.
std::string GenerateArrayScript(const SlurmGenerateLayout& layout, const SlurmOptions& options);
// The final job: `handdb unit finalize` (manifest + validation).
std::string GenerateFinalScript(const SlurmGenerateLayout& layout, const SlurmOptions& options);

// Shell-quotes a word for bash ('...' with embedded quotes escaped).
std::string ShellQuote(const std::string& word);
// A command line as one would type it (words quoted only when needed), for messages.
std::string FormatCommand(const std::vector<std::string>& argv);

// ---- Talking to Slurm ---------------------------------------------------------------------------

// Output of a command run without a shell. Errors (not found, non-zero exit) name the command
// and carry its stderr.
struct CommandOutput {
  int exit_code = 0;
  std::string out;
  std::string err;
};
Result<CommandOutput> RunCommand(const std::vector<std::string>& argv);

// `sbatch --parsable ARGS... SCRIPT SCRIPT_ARGS...` -> the job id.
Result<std::string> SubmitBatch(const std::vector<std::string>& sbatch_args,
                                const std::filesystem::path& script,
                                const std::vector<std::string>& script_args);

// MaxArraySize from `scontrol show config` (Slurm's default 1001 if not reported).
Result<uint32_t> QueryMaxArraySize();

// One job (or array task) as `scontrol -o show job` reports it.
struct SlurmJobState {
  std::string job_id;        // "123" or, for an array task, the task's own id
  std::string array_job_id;  // empty for a non-array job
  int64_t array_task_id = -1;
  std::string state;  // PENDING, RUNNING, COMPLETED, FAILED, CANCELLED, TIMEOUT, ...
  std::string reason;
  std::string exit_code;  // "0:0"
  std::string std_out;    // StdOut path
};
// Parses `scontrol -o show job` output (one job per line; a pending array may be one line with
// ArrayTaskId=0-3). Pure, for tests.
std::vector<SlurmJobState> ParseScontrolJobs(const std::string& text);
// Jobs Slurm still knows of (finished jobs are forgotten after MinJobAge): an unknown id is not
// an error, it yields no entry.
Result<std::vector<SlurmJobState>> QueryJobs(const std::vector<std::string>& job_ids);
// True for states after which a job no longer runs.
bool IsFinishedJobState(const std::string& state);

// ---- handdb generate --slurm -------------------------------------------------------------------

// A previous or new submission, recorded in slurm/jobs.json so a re-run can tell whether jobs
// are still running and a report can name their Slurm ids.
struct SlurmSubmission {
  std::string db_dir;                                     // the database the jobs build
  std::vector<std::string> array_job_ids;                 // one per chunk
  std::vector<uint32_t> chunk_bases;                      // parallel to array_job_ids
  std::string final_job_id;                               // empty in a dry run
  std::vector<uint32_t> units;                            // the units submitted
  std::vector<std::vector<std::string>> sbatch_commands;  // what was (or would be) run
};
Status WriteSubmissionRecord(const std::filesystem::path& path, const SlurmSubmission& sub);
Result<SlurmSubmission> ReadSubmissionRecord(const std::filesystem::path& path);

// Writes both scripts (atomically) and, unless `dry_run`, submits the array chunks for `units` and
// the final job (afterok on every chunk). With no units, only the final job is submitted.
Result<SlurmSubmission> SubmitGenerateJobs(const SlurmGenerateLayout& layout,
                                           const SlurmOptions& options,
                                           const std::vector<uint32_t>& units,
                                           bool dry_run);

// Submits one array job per chunk of `indices` (PlanArrayChunks; each task gets its chunk's base
// as the script's argument $1) and a final job with --dependency=afterok on all of them (alone,
// without a dependency, when `indices` is empty). The scripts must exist. Unless `dry_run`, records
// the submission in `jobs_file`. `target` names what the jobs build (SlurmSubmission::db_dir).
Result<SlurmSubmission> SubmitArrayWithFinal(const std::filesystem::path& array_script,
                                             const std::filesystem::path& final_script,
                                             const std::filesystem::path& jobs_file,
                                             const std::string& target,
                                             const SlurmOptions& options,
                                             const std::vector<uint32_t>& indices,
                                             bool dry_run);

// ---- handdb evaluate --slurm -------------------------------------------------------------------

// Where a Slurm evaluation keeps its files (WORK = the evaluation's work directory).
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

  std::filesystem::path array_script() const { return work_dir / "evaluate-array.sbatch"; }
  std::filesystem::path final_script() const { return work_dir / "evaluate-merge.sbatch"; }
  std::filesystem::path log_dir() const { return work_dir / "logs"; }
  std::filesystem::path failed_dir() const { return work_dir / "failed"; }
  std::filesystem::path jobs_file() const { return work_dir / "jobs.json"; }
  std::filesystem::path report_text() const { return work_dir / "report.txt"; }
  // logs/part-00007.log (all attempts at task 7), failed/part-00007 (why the last one failed).
  std::filesystem::path TaskLog(uint32_t task) const;
  std::filesystem::path TaskFailedMarker(uint32_t task) const;
  std::filesystem::path final_log() const { return log_dir() / "merge.log"; }
};

// The array script: argument $1 is the chunk's base; task BASE + SLURM_ARRAY_TASK_ID runs
// `handdb unit evaluate ... --task T` (a no-op when its part is already complete) and records a
// failure marker with the exit code when it fails.
std::string EvaluateArrayScript(const SlurmEvaluateLayout& layout, const SlurmOptions& options);
// The final job: `handdb unit evaluate-merge ...` (report text, JSON, plots).
std::string EvaluateFinalScript(const SlurmEvaluateLayout& layout, const SlurmOptions& options);

// Why a unit is incomplete after its task ran: from the failure marker and Slurm's job state.
struct UnitFailure {
  uint32_t unit = 0;
  std::string reason;  // "exit code 1 in `handdb unit render`", "TIMEOUT", ...
  std::filesystem::path log;
};
// One line per failure: "unit 7: <reason>; log: <path>".
std::string FormatUnitFailure(const UnitFailure& failure);

}  // namespace handdb
