// What the two Slurm front ends share: `handdb generate --slurm` (cli/slurm_commands.cc) and
// `handdb evaluate --slurm` (cli/evaluate_slurm_commands.cc), and their `handdb unit ...` tasks.
// Both submit an array plus a final job recorded in a jobs.json, refuse to submit while an earlier
// submission still runs, wait with --wait and report each array task that left no output; one
// copy of that logic keeps the two commands' messages and failure reports alike.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "cli/slurm_commands.h"
#include "base/status.h"
#include "cluster/slurm.h"

namespace handdb::cli {

// Threads for a task: what Slurm gave it ($SLURM_CPUS_PER_TASK), else 1.
int TaskThreads();

// `p` absolute and normalised, without a trailing separator ("db/" -> "/abs/db").
Result<std::filesystem::path> Absolute(const std::filesystem::path& p);

// The running handdb executable (what the jobs run on the shared filesystem).
Result<std::filesystem::path> SelfExecutable();

// The SlurmOptions of --partition, --time, --mem, ... with --time and --slurm-setup checked.
Result<SlurmOptions> OptionsFromFlags(const SlurmFlags& flags);

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

// Where an array task keeps its log and failure marker, and what it writes ("shard", "part").
struct TaskFiles {
  std::function<std::filesystem::path(uint32_t)> log;
  std::function<std::filesystem::path(uint32_t)> failed_marker;
  std::filesystem::path log_dir;  // Slurm's own output files, when a task has no log of its own
  std::string output;
};
// Why each unit of `sub` that is not `complete` has no output: from its failure marker and
// Slurm's state of its array task; the log to read (the task's own, else Slurm's output file).
std::vector<UnitFailure> CollectFailures(const TaskFiles& files,
                                         const SlurmSubmission& sub,
                                         const std::vector<bool>& complete,
                                         const std::vector<SlurmJobState>& jobs);

}  // namespace handdb::cli
