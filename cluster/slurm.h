// Scale-out on a real cluster engine: work as a Slurm job array plus one final job.
//
// The caller (cli/) describes the work as task command lines (SlurmArrayJob); this file knows
// nothing of what they compute. Array task i runs the task commands for index BASE + i, then one
// final job, dependent on the array with afterok, runs the final command. Every task is idempotent;
// a re-run submits only the indices whose output is missing (the caller computes them from disk).
//
// It holds the parts that do not depend on a running cluster (the array index list, the script
// text, option checks), the thin layer that talks to Slurm through its ordinary commands
// (sbatch --parsable, scontrol -o show job), so it works against any Slurm >= 20, and the
// submission records, waiting and failure reports built on it.
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
// index below `max_array_size` (base = a multiple of max_array_size; fewer units than
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

// ---- Job scripts -------------------------------------------------------------------------------

// <prefix>00007: the one rule for a task's names (its log, failure marker, evaluation part).
std::string SlurmTaskName(const std::string& prefix, uint32_t task);

// Where one submission (an array of tasks plus a final job) keeps its files; the caller names
// them. All paths absolute: they are read on compute nodes.
struct SlurmArrayLayout {
  std::filesystem::path dir;      // scripts, logs/, failed/, jobs.json
  std::string array_script_name;  // the array's sbatch script, in `dir`
  std::string final_script_name;  // the final job's sbatch script, in `dir`
  std::string final_log_name;     // the final job's log, in logs/
  std::string task_prefix;        // task 7's files are logs/<prefix>00007.log, failed/<prefix>00007

  std::filesystem::path array_script() const { return dir / array_script_name; }
  std::filesystem::path final_script() const { return dir / final_script_name; }
  std::filesystem::path log_dir() const { return dir / "logs"; }
  std::filesystem::path failed_dir() const { return dir / "failed"; }
  std::filesystem::path jobs_file() const { return dir / "jobs.json"; }
  std::filesystem::path final_log() const { return log_dir() / final_log_name; }
  // SlurmTaskName(task_prefix, task), here and in the array script.
  std::string TaskName(uint32_t task) const { return SlurmTaskName(task_prefix, task); }
  // The log every attempt at task `task` appends to.
  std::filesystem::path TaskLog(uint32_t task) const;
  // Written by a task that failed (exit code, job id, host); removed when it succeeds.
  std::filesystem::path TaskFailedMarker(uint32_t task) const;
};

// A shell variable the scripts set before their commands: NAME='value' or NAME=('a' 'b').
struct ScriptVariable {
  std::string name;
  std::vector<std::string> words;
  bool is_array = false;
};

// One command of an array task: bash text in which "$task" is the task's index
// (BASE + SLURM_ARRAY_TASK_ID) and the script's variables are set.
struct TaskCommand {
  std::string line;
  std::string what;  // names it in the failure marker: "exit code 1 from <what>"
};

// What the array and final job scripts run; the caller (cli/) fills it in.
struct SlurmArrayJob {
  SlurmArrayLayout layout;
  std::filesystem::path chdir;   // every job runs here
  std::string generated_by;      // the command that wrote the scripts, for their comments
  std::string array_job_suffix;  // appended to SlurmOptions::job_name ("" or "-x")
  std::string final_job_suffix;
  std::string array_comment;  // "# ..." lines: what array task i does
  std::string final_comment;  // completes "runs after every array task succeeded: ..."
  std::string task_noun;      // names a task in its log: "=== <noun> 7: ..."
  std::string final_noun;     // names the final job in its log
  std::vector<ScriptVariable> array_variables;
  std::vector<ScriptVariable> final_variables;
  std::vector<TaskCommand> task_commands;  // in order; the first that fails ends the task
  std::string final_command;               // the final job's exit code is this command's
};

// The sbatch script of the array: argument $1 is the chunk's base. Each task runs the task
// commands, logging to its own log, and records a failure marker with the exit code when one fails.
std::string ArrayScript(const SlurmArrayJob& job, const SlurmOptions& options);
// The final job: the final command, its exit code the job's.
std::string FinalScript(const SlurmArrayJob& job, const SlurmOptions& options);
// Creates the layout's directories and writes both scripts (atomically).
Status WriteJobScripts(const SlurmArrayJob& job, const SlurmOptions& options);

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

// ---- Submissions -------------------------------------------------------------------------------

// A previous or new submission, recorded in slurm/jobs.json so a re-run can tell whether jobs
// are still running and a report can name their Slurm ids.
struct SlurmSubmission {
  std::string db_dir;                                     // what the jobs build (the target)
  std::vector<std::string> array_job_ids;                 // one per chunk
  std::vector<uint32_t> chunk_bases;                      // parallel to array_job_ids
  std::string final_job_id;                               // empty in a dry run
  std::vector<uint32_t> units;                            // the units submitted
  std::vector<std::vector<std::string>> sbatch_commands;  // what was (or would be) run
};
Status WriteSubmissionRecord(const std::filesystem::path& path, const SlurmSubmission& sub);
Result<SlurmSubmission> ReadSubmissionRecord(const std::filesystem::path& path);

// Submits one array job per chunk of `indices` (PlanArrayChunks; each task gets its chunk's base
// as the script's argument $1) and a final job with --dependency=afterok on all of them (alone,
// without a dependency, when `indices` is empty). The scripts must exist. Unless `dry_run`, records
// the submission in the layout's jobs file. `target` names what the jobs build
// (SlurmSubmission::db_dir).
Result<SlurmSubmission> SubmitArrayWithFinal(const SlurmArrayLayout& layout,
                                             const std::string& target,
                                             const SlurmOptions& options,
                                             const std::vector<uint32_t>& indices,
                                             bool dry_run);

// "a,b,c" (or joined by `sep`).
std::string JoinIds(const std::vector<std::string>& ids, const char* sep = ",");

// The array job ids and the final job id of a submission.
std::vector<std::string> JobIds(const SlurmSubmission& sub);

// Jobs of `sub` Slurm still runs or queues (array job ids for arrays); `states` (if not null)
// gets every job state Slurm reports.
Result<std::vector<std::string>> ActiveJobs(const SlurmSubmission& sub,
                                            std::vector<SlurmJobState>* states);

// The submission an earlier run recorded in its jobs.json, with its jobs' states.
struct PreviousSubmission {
  bool exists = false;  // false: no jobs.json yet
  SlurmSubmission sub;
  std::vector<SlurmJobState> states;
};
// Reads `jobs_file` if it exists. An error when any of its jobs is still queued or running (two
// tasks on one unit would do the work twice); `of_what` completes "an earlier submission ...",
// e.g. "for /data/db".
Result<PreviousSubmission> CheckPreviousSubmission(const std::filesystem::path& jobs_file,
                                                   const std::string& of_what);

// --wait: polls Slurm every `poll_seconds` until every job of `sub` has ended, showing finished
// array tasks (of `num_tasks`) as progress. Returns the last job states.
Result<std::vector<SlurmJobState>> WaitForJobs(const SlurmSubmission& sub,
                                               uint64_t num_tasks,
                                               double poll_seconds,
                                               bool show_progress);

// The state of `sub`'s final job in `states` ("unknown" when Slurm no longer reports it).
std::string FinalJobState(const SlurmSubmission& sub, const std::vector<SlurmJobState>& states);

// The text of `path` without trailing line ends; empty when it cannot be read.
std::string ReadTrimmed(const std::filesystem::path& path);

// ---- Failure reports ---------------------------------------------------------------------------

// Why a unit is incomplete after its task ran: from the failure marker and Slurm's job state.
struct UnitFailure {
  uint32_t unit = 0;
  std::string reason;  // the failure marker's text, "TIMEOUT", ...
  std::filesystem::path log;
};
// One line per failure: "unit 7: <reason>; log: <path>".
std::string FormatUnitFailure(const UnitFailure& failure);

// Why each unit of `sub` that is not `complete` has no `output` (what a task writes, for
// messages): from its failure marker in `layout` and Slurm's state of its array task; the log to
// read (the task's own, else Slurm's output file).
std::vector<UnitFailure> CollectFailures(const SlurmArrayLayout& layout,
                                         const std::string& output,
                                         const SlurmSubmission& sub,
                                         const std::vector<bool>& complete,
                                         const std::vector<SlurmJobState>& jobs);

}  // namespace handdb
