#include "cli/slurm_cli.h"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <map>
#include <set>
#include <thread>

#include "base/atomic_file.h"
#include "base/progress.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;

// The Slurm state of each array task of a submission, keyed by unit (the last report wins).
std::map<uint32_t, SlurmJobState> TaskStatesByUnit(const SlurmSubmission& sub,
                                                   const std::vector<SlurmJobState>& jobs) {
  std::map<uint32_t, SlurmJobState> by_unit;
  for (size_t c = 0; c < sub.array_job_ids.size() && c < sub.chunk_bases.size(); ++c) {
    for (const auto& j : jobs) {
      if (j.array_job_id == sub.array_job_ids[c] && j.array_task_id >= 0) {
        by_unit[sub.chunk_bases[c] + static_cast<uint32_t>(j.array_task_id)] = j;
      }
    }
  }
  return by_unit;
}

}  // namespace

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
  SlurmOptions options;
  options.partition = flags.partition;
  options.max_parallel = flags.max_parallel;
  options.time_limit = flags.time;
  options.mem_per_task = flags.mem;
  options.cpus_per_task = flags.cpus_per_task;
  options.sbatch_args = flags.sbatch_args;
  if (!flags.time.empty() && !IsValidSlurmTime(flags.time)) {
    return Status(
        StatusCode::kInvalidArgument,
        "--time '" + flags.time + "': not a Slurm time (M, M:S, H:M:S, D-H, D-H:M or D-H:M:S)");
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

std::string JoinIds(const std::vector<std::string>& ids, const char* sep) {
  std::string out;
  for (const auto& id : ids) out += (out.empty() ? "" : sep) + id;
  return out;
}

std::vector<std::string> JobIds(const SlurmSubmission& sub) {
  std::vector<std::string> ids = sub.array_job_ids;
  if (!sub.final_job_id.empty()) ids.push_back(sub.final_job_id);
  return ids;
}

Result<std::vector<std::string>> ActiveJobs(const SlurmSubmission& sub,
                                            std::vector<SlurmJobState>* states) {
  auto jobs = QueryJobs(JobIds(sub));
  if (!jobs.ok()) return jobs.status();
  std::set<std::string> active;
  for (const auto& j : *jobs) {
    if (IsFinishedJobState(j.state)) continue;
    active.insert(j.array_job_id.empty() ? j.job_id : j.array_job_id);
  }
  if (states != nullptr) *states = *jobs;
  return std::vector<std::string>(active.begin(), active.end());
}

Result<PreviousSubmission> CheckPreviousSubmission(const fs::path& jobs_file,
                                                   const std::string& of_what) {
  PreviousSubmission previous;
  std::error_code ec;
  if (!fs::exists(jobs_file, ec)) return previous;
  auto sub = ReadSubmissionRecord(jobs_file);
  if (!sub.ok()) return sub.status();
  previous.exists = true;
  previous.sub = std::move(*sub);
  auto active = ActiveJobs(previous.sub, &previous.states);
  if (!active.ok()) return active.status();
  if (!active->empty()) {
    return Status(StatusCode::kInvalidArgument,
                  "Slurm jobs " + JoinIds(*active, ", ") + " of an earlier submission " + of_what +
                      " are still queued or running; wait for them (squeue -j " + JoinIds(*active) +
                      ") or cancel them (scancel " + JoinIds(*active, " ") +
                      ") and run this again");
  }
  return previous;
}

Result<std::vector<SlurmJobState>> WaitForJobs(const SlurmSubmission& sub,
                                               uint64_t num_tasks,
                                               double poll_seconds,
                                               bool show_progress) {
  Progress progress("slurm", num_tasks, show_progress, "tasks");
  std::vector<SlurmJobState> states;
  uint64_t shown = 0;
  while (true) {
    auto active = ActiveJobs(sub, &states);
    if (!active.ok()) return active.status();
    uint64_t finished = 0;
    for (const auto& j : states) {
      if (!j.array_job_id.empty() && j.array_task_id >= 0 && IsFinishedJobState(j.state)) {
        ++finished;
      }
    }
    finished = std::min<uint64_t>(finished, num_tasks);
    if (finished > shown) {
      progress.Add(finished - shown);
      shown = finished;
    }
    if (active->empty()) return states;
    std::this_thread::sleep_for(std::chrono::duration<double>(poll_seconds));
  }
}

std::string FinalJobState(const SlurmSubmission& sub, const std::vector<SlurmJobState>& states) {
  std::string final_state = "unknown";
  for (const auto& j : states) {
    if (j.job_id == sub.final_job_id) final_state = j.state;
  }
  return final_state;
}

std::string ReadTrimmed(const fs::path& path) {
  auto text = ReadFileToString(path);
  if (!text.ok()) return "";
  std::string s = *text;
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  return s;
}

std::vector<UnitFailure> CollectFailures(const TaskFiles& files,
                                         const SlurmSubmission& sub,
                                         const std::vector<bool>& complete,
                                         const std::vector<SlurmJobState>& jobs) {
  const auto states = TaskStatesByUnit(sub, jobs);
  std::vector<UnitFailure> failures;
  for (uint32_t u : sub.units) {
    if (u < complete.size() && complete[u]) continue;
    UnitFailure f;
    f.unit = u;
    f.log = files.log(u);
    const std::string marker = ReadTrimmed(files.failed_marker(u));
    const auto it = states.find(u);
    if (it != states.end() && !IsFinishedJobState(it->second.state)) {
      f.reason = "still " + it->second.state;
    } else if (!marker.empty()) {
      f.reason = marker;
      if (it != states.end()) f.reason += " [Slurm: " + it->second.state + "]";
    } else if (it != states.end()) {
      f.reason = "Slurm task " + it->second.job_id + " ended " + it->second.state + " (exit " +
                 it->second.exit_code + ") without a " + files.output;
    } else {
      f.reason = "no " + files.output + " written (Slurm no longer reports the task)";
    }
    std::error_code ec;
    if (!fs::exists(f.log, ec)) {
      // The task never reached its own log: Slurm's output file is the place to look.
      f.log = it != states.end() && !it->second.std_out.empty() ? fs::path(it->second.std_out)
                                                                : files.log_dir;
    }
    failures.push_back(std::move(f));
  }
  return failures;
}

}  // namespace handdb::cli
