// `handdb evaluate --slurm` and the two worker commands its jobs run, `handdb unit evaluate` (one
// array task: one slice of the test views -> WORK/parts/part-0000T.json) and
// `handdb unit evaluate-merge` (the final job: parts -> the report of a local run). Issue 7,
// docs/cluster.md.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>

#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/evaluate_cli.h"
#include "format/atomic_file.h"
#include "format/json_schema.h"
#include "format/progress.h"
#include "generator/slurm.h"
#include "query/eval_parts.h"
#include "query/searcher.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr uint32_t kViewsPerTask = 16;  // default split: tasks of a few seconds to minutes
constexpr uint32_t kMaxDefaultTasks = 1000;

// Threads for a task: what Slurm gave it, else 1.
int TaskThreads() {
  if (const char* c = std::getenv("SLURM_CPUS_PER_TASK")) {
    const int n = std::atoi(c);
    if (n > 0) return n;
  }
  return 1;
}

double UnixNow() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

Result<fs::path> Absolute(const fs::path& p) {
  std::error_code ec;
  fs::path a = fs::absolute(p, ec);
  if (ec) return Status(StatusCode::kIoError, p.string() + ": " + ec.message());
  a = a.lexically_normal();
  if (!a.has_filename() && a.has_parent_path()) a = a.parent_path();
  return a;
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

std::string JoinIds(const std::vector<std::string>& ids, const char* sep = ",") {
  std::string out;
  for (const auto& id : ids) out += (out.empty() ? "" : sep) + id;
  return out;
}

std::vector<std::string> JobIds(const SlurmSubmission& sub) {
  std::vector<std::string> ids = sub.array_job_ids;
  if (!sub.final_job_id.empty()) ids.push_back(sub.final_job_id);
  return ids;
}

// Jobs of `sub` Slurm still runs or queues (array job ids for arrays).
Result<std::vector<std::string>> ActiveJobs(const SlurmSubmission& sub,
                                            std::vector<SlurmJobState>* states) {
  auto jobs = QueryJobs(JobIds(sub));
  if (!jobs.ok()) return jobs.status();
  std::set<std::string> active;
  for (const auto& j : *jobs) {
    if (!IsFinishedJobState(j.state))
      active.insert(j.array_job_id.empty() ? j.job_id : j.array_job_id);
  }
  if (states != nullptr) *states = *jobs;
  return std::vector<std::string>(active.begin(), active.end());
}

std::string ReadTrimmed(const fs::path& path) {
  auto text = ReadFileToString(path);
  if (!text.ok()) return "";
  std::string s = *text;
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  return s;
}

// One line per task of `sub` without a complete part: "task 3: <reason>; log: <path>".
std::vector<std::string> TaskFailures(const SlurmEvaluateLayout& layout,
                                      const SlurmSubmission& sub,
                                      const std::vector<bool>& complete,
                                      const std::vector<SlurmJobState>& jobs) {
  std::vector<std::string> lines;
  for (uint32_t t : sub.units) {
    if (t < complete.size() && complete[t]) continue;
    const SlurmJobState* state = nullptr;
    for (size_t c = 0; c < sub.array_job_ids.size() && c < sub.chunk_bases.size(); ++c) {
      for (const auto& j : jobs) {
        if (j.array_job_id == sub.array_job_ids[c] && j.array_task_id >= 0 &&
            sub.chunk_bases[c] + static_cast<uint32_t>(j.array_task_id) == t) {
          state = &j;
        }
      }
    }
    std::string reason;
    const std::string marker = ReadTrimmed(layout.TaskFailedMarker(t));
    if (state != nullptr && !IsFinishedJobState(state->state)) {
      reason = "still " + state->state;
    } else if (!marker.empty()) {
      reason = marker + (state != nullptr ? " [Slurm: " + state->state + "]" : "");
    } else if (state != nullptr) {
      reason = "Slurm task " + state->job_id + " ended " + state->state + " (exit " +
               state->exit_code + ") without a part";
    } else {
      reason = "no part written (Slurm no longer reports the task)";
    }
    std::error_code ec;
    fs::path log = layout.TaskLog(t);
    if (!fs::exists(log, ec)) {
      log =
          state != nullptr && !state->std_out.empty() ? fs::path(state->std_out) : layout.log_dir();
    }
    lines.push_back("task " + std::to_string(t) + ": " + reason + "; log: " + log.string());
  }
  return lines;
}

// The merge job's own one-line error, if its log has one.
std::string MergeError(const SlurmEvaluateLayout& layout) {
  const std::string log = ReadTrimmed(layout.final_log());
  std::string found;
  size_t pos = 0;
  while (pos < log.size()) {
    size_t end = log.find('\n', pos);
    if (end == std::string::npos) end = log.size();
    const std::string line = log.substr(pos, end - pos);
    if (line.rfind("handdb unit evaluate-merge: ", 0) == 0) found = line;
    pos = end + 1;
  }
  return found;
}

// Parts 0..N-1 of WORK: complete (true) or to be computed (false); a part of another evaluation
// is an error naming the file.
Result<std::vector<bool>> CompleteParts(const fs::path& work,
                                        const EvaluationFingerprint& fp,
                                        const std::vector<uint32_t>& selected,
                                        uint32_t num_tasks,
                                        size_t num_criteria) {
  std::vector<bool> complete(num_tasks, false);
  for (uint32_t t = 0; t < num_tasks; ++t) {
    PartExpectation expect;
    expect.fingerprint = fp;
    expect.task = t;
    expect.slice = TaskSlice(selected, t, num_tasks);
    expect.num_criteria = num_criteria;
    auto part = ReadPart(PartPath(work, t), expect);
    // A part of another evaluation is refused (it would be overwritten); anything else that is
    // not a complete part (absent, unreadable, truncated) is work for the part's task.
    if (part.ok()) {
      complete[t] = true;
    } else if (part.status().code() == StatusCode::kInvalidArgument) {
      return part.status();
    }
  }
  return complete;
}

}  // namespace

int RunEvaluateOnSlurm(const EvaluateSlurmRequest& request, const SlurmFlags& flags) {
  const char* cmd = "evaluate";
  auto options = OptionsFromFlags(flags);
  if (!options.ok()) return Fail(cmd, options.status());
  const EvaluationOptions& eval = request.flags.options;
  const QueryInput input = request.flags.query_input();

  auto testset = ReadTestSet(request.testset);
  if (!testset.ok()) return Fail(cmd, testset.status());
  {
    // Fail on the login node, not in every task, when the database does not open.
    auto db = Database::Open(request.db);
    if (!db.ok()) return Fail(cmd, db.status());
  }
  WarnIfTestSetMatchesDatabase(request.db, *testset);
  const std::vector<uint32_t> selected = SelectTestViews(*testset, eval);
  if (selected.empty()) {
    return Fail(cmd,
                Status(StatusCode::kInvalidArgument,
                       testset->file.string() + ": no test views to evaluate"));
  }
  const uint32_t num_selected = static_cast<uint32_t>(selected.size());
  uint32_t tasks = request.tasks;
  if (tasks == 0) {
    tasks = std::min(kMaxDefaultTasks, (num_selected + kViewsPerTask - 1) / kViewsPerTask);
  }
  if (tasks > num_selected) {
    std::fprintf(stderr,
                 "handdb %s: --tasks %u: more tasks than the %u selected test views\n",
                 cmd,
                 tasks,
                 num_selected);
    return kExitUsage;
  }
  auto fp = ComputeEvaluationFingerprint(request.db, *testset, input, eval, tasks);
  if (!fp.ok()) return Fail(cmd, fp.status());

  SlurmEvaluateLayout layout;
  {
    std::error_code ec;
    fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (ec) {
      return Fail(cmd,
                  Status(StatusCode::kIoError,
                         "/proc/self/exe: cannot find the handdb executable: " + ec.message()));
    }
    layout.handdb = exe;
    layout.submit_dir = fs::current_path(ec);
    if (ec) return Fail(cmd, Status(StatusCode::kIoError, "current directory: " + ec.message()));
    auto work = Absolute(request.work.empty() ? testset->dir / "slurm-evaluations" / fp->value
                                              : request.work);
    if (!work.ok()) return Fail(cmd, work.status());
    layout.work_dir = *work;
  }
  std::vector<std::string> common = {request.db,
                                     request.testset,
                                     "--tasks",
                                     std::to_string(tasks),
                                     "--work",
                                     layout.work_dir.string()};
  const auto eval_args = request.flags.Args();
  common.insert(common.end(), eval_args.begin(), eval_args.end());
  layout.task_args = {"unit", "evaluate"};
  layout.task_args.insert(layout.task_args.end(), common.begin(), common.end());
  layout.merge_args = {"unit", "evaluate-merge"};
  layout.merge_args.insert(layout.merge_args.end(), common.begin(), common.end());
  if (!request.json_out.empty()) {
    layout.merge_args.insert(layout.merge_args.end(), {"--json", request.json_out});
  }
  if (!request.plots_dir.empty()) {
    layout.merge_args.insert(layout.merge_args.end(), {"--plots", request.plots_dir});
  }

  // An earlier submission still running must end first (two tasks on one part do the work twice).
  std::error_code ec;
  SlurmSubmission previous;
  bool have_previous = false;
  std::vector<SlurmJobState> previous_states;
  if (!flags.dry_run && fs::exists(layout.jobs_file(), ec)) {
    auto prev = ReadSubmissionRecord(layout.jobs_file());
    if (!prev.ok()) return Fail(cmd, prev.status());
    previous = *prev;
    have_previous = true;
    auto active = ActiveJobs(previous, &previous_states);
    if (!active.ok()) return Fail(cmd, active.status());
    if (!active->empty()) {
      return Fail(
          cmd,
          Status(StatusCode::kInvalidArgument,
                 "Slurm jobs " + JoinIds(*active, ", ") +
                     " of an earlier submission of this evaluation (" + layout.work_dir.string() +
                     ") are still queued or running; wait for them (squeue -j " + JoinIds(*active) +
                     ") or cancel them (scancel " + JoinIds(*active, " ") +
                     ") and run this again"));
    }
  }

  const size_t num_criteria = MakeCriteria(eval).size();
  auto complete = CompleteParts(layout.work_dir, *fp, selected, tasks, num_criteria);
  if (!complete.ok()) return Fail(cmd, complete.status());
  const auto pending =
      PendingUnits(tasks, [&](uint32_t t) { return static_cast<bool>((*complete)[t]); });
  if (have_previous) {
    for (const auto& line : TaskFailures(layout, previous, *complete, previous_states)) {
      std::fprintf(stderr, "handdb %s: earlier Slurm run: %s\n", cmd, line.c_str());
    }
  }

  for (const auto& dir : {layout.work_dir,
                          layout.log_dir(),
                          layout.failed_dir(),
                          PartPath(layout.work_dir, 0).parent_path()}) {
    fs::create_directories(dir, ec);
    if (ec) {
      return Fail(cmd,
                  Status(StatusCode::kIoError, dir.string() + ": cannot create: " + ec.message()));
    }
  }
  Status s = WriteFileAtomic(layout.array_script(), EvaluateArrayScript(layout, *options));
  if (s.ok()) s = WriteFileAtomic(layout.final_script(), EvaluateFinalScript(layout, *options));
  if (!s.ok()) return Fail(cmd, s);
  if (!flags.dry_run) {
    auto max_array = QueryMaxArraySize();
    if (!max_array.ok()) return Fail(cmd, max_array.status());
    options->max_array_size = *max_array;
    // Markers of tasks about to be resubmitted describe an old attempt; a report of an old merge
    // must not pass for the new one.
    for (uint32_t t : pending) fs::remove(layout.TaskFailedMarker(t), ec);
    fs::remove(layout.report_text(), ec);
  }
  auto sub = SubmitArrayWithFinal(layout.array_script(),
                                  layout.final_script(),
                                  layout.jobs_file(),
                                  layout.work_dir.string(),
                                  *options,
                                  pending,
                                  flags.dry_run);
  if (!sub.ok()) return Fail(cmd, sub.status());

  const std::string tasks_text = pending.empty() ? "none" : FormatArrayRanges(pending);
  if (flags.dry_run) {
    std::printf(
        "dry run: %u test views in %u tasks, %zu to run (%s); work directory %s; scripts:\n"
        "  %s\n  %s\nwould run:\n",
        num_selected,
        tasks,
        pending.size(),
        tasks_text.c_str(),
        layout.work_dir.c_str(),
        layout.array_script().c_str(),
        layout.final_script().c_str());
    for (const auto& c : sub->sbatch_commands) std::printf("  %s\n", FormatCommand(c).c_str());
    return kExitOk;
  }
  if (!request.quiet) {
    std::fprintf(stderr,
                 "handdb %s: submitted %zu of %u tasks (%s) as array job%s %s, merge job %s; "
                 "work directory %s\n",
                 cmd,
                 pending.size(),
                 tasks,
                 tasks_text.c_str(),
                 sub->array_job_ids.size() == 1 ? "" : "s",
                 JoinIds(sub->array_job_ids).c_str(),
                 sub->final_job_id.c_str(),
                 layout.work_dir.c_str());
  }
  if (!flags.wait) {
    std::printf(
        "submitted: array job(s) %s, merge job %s; the report will be in %s. Run the same "
        "command again to see failures and resubmit only the missing parts.\n",
        sub->array_job_ids.empty() ? "none" : JoinIds(sub->array_job_ids).c_str(),
        sub->final_job_id.c_str(),
        layout.report_text().c_str());
    return kExitOk;
  }

  // --wait: poll until every job has ended, finished tasks as progress.
  std::vector<SlurmJobState> states;
  {
    Progress progress("slurm", pending.size(), !request.quiet, "tasks");
    uint64_t shown = 0;
    while (true) {
      auto active = ActiveJobs(*sub, &states);
      if (!active.ok()) return Fail(cmd, active.status());
      uint64_t finished = 0;
      for (const auto& j : states) {
        if (!j.array_job_id.empty() && j.array_task_id >= 0 && IsFinishedJobState(j.state)) {
          ++finished;
        }
      }
      finished = std::min<uint64_t>(finished, pending.size());
      if (finished > shown) {
        progress.Add(finished - shown);
        shown = finished;
      }
      if (active->empty()) break;
      std::this_thread::sleep_for(std::chrono::duration<double>(flags.poll_seconds));
    }
  }
  auto after = CompleteParts(layout.work_dir, *fp, selected, tasks, num_criteria);
  if (!after.ok()) return Fail(cmd, after.status());
  const auto failures = TaskFailures(layout, *sub, *after, states);
  for (const auto& line : failures) std::fprintf(stderr, "handdb %s: %s\n", cmd, line.c_str());
  if (!failures.empty()) {
    return Fail(cmd,
                Status(StatusCode::kExternalToolFailed,
                       std::to_string(failures.size()) + " of " + std::to_string(pending.size()) +
                           " Slurm tasks failed (listed above); run the same command again to "
                           "resubmit only the missing parts"));
  }
  auto report = ReadFileToString(layout.report_text());
  if (!report.ok()) {
    std::string final_state = "unknown";
    for (const auto& j : states) {
      if (j.job_id == sub->final_job_id) final_state = j.state;
    }
    const std::string why = MergeError(layout);
    return Fail(cmd,
                Status(StatusCode::kExternalToolFailed,
                       "merge job " + sub->final_job_id + " ended " + final_state +
                           " without a report" + (why.empty() ? "" : " (" + why + ")") +
                           "; log: " + layout.final_log().string()));
  }
  if (!request.quiet) std::printf("%s", report->c_str());
  return kExitOk;
}

UnitEvaluateCommands::UnitEvaluateCommands(CLI::App& unit_app) {
  task_cmd_ = unit_app.add_subcommand(
      "evaluate",
      "score one slice of a test set, as array task T of `handdb evaluate --slurm` does: the "
      "selected test views at positions k with k % TASKS == T, into WORK/parts/part-0000T.json "
      "(kept when already complete)");
  merge_cmd_ = unit_app.add_subcommand(
      "evaluate-merge",
      "merge the parts of `handdb evaluate --slurm` into the report a local run writes: text on "
      "stdout and in WORK/report.txt, --json, --plots");
  for (CLI::App* app : {task_cmd_, merge_cmd_}) {
    app->add_option("db", db_, "database directory")->required();
    app->add_option("testset", testset_, "test-set directory (or its testset.json)")->required();
    app->add_option("--tasks", tasks_, "number of tasks the test views are split over")
        ->required()
        ->check(CLI::Range(1, 100000));
    app->add_option("--work", work_, "the evaluation's work directory (parts/ inside)")->required();
    flags_.Add(*app);
    app->add_flag("-q,--quiet", quiet_, "no progress (merge: no text report on stdout)");
  }
  task_cmd_->add_option("--task", task_, "this task's number (0-based)")->required();
  merge_cmd_->add_option(
      "--json", json_out_, "write the full report (schemas/evaluation.schema.json)");
  merge_cmd_->add_option("--plots", plots_dir_, "write PNG plots and example sheets here");
}

bool UnitEvaluateCommands::parsed() const { return task_cmd_->parsed() || merge_cmd_->parsed(); }

int UnitEvaluateCommands::Run() {
  const bool merge = merge_cmd_->parsed();
  const std::string cmd_name = merge ? "unit evaluate-merge" : "unit evaluate";
  const char* cmd = cmd_name.c_str();
  if (!flags_.Finish(cmd_name, quiet_)) return kExitUsage;
  EvaluationOptions& options = flags_.options;
  if (!merge && options.num_threads == -1) options.num_threads = TaskThreads();
  if (!merge && task_ >= tasks_) {
    std::fprintf(stderr, "handdb %s: --task %u: must be below --tasks %u\n", cmd, task_, tasks_);
    return kExitUsage;
  }
  const QueryInput input = flags_.query_input();
  auto testset = ReadTestSet(testset_);
  if (!testset.ok()) return Fail(cmd, testset.status());
  auto searcher = Searcher::Open(db_);
  if (!searcher.ok()) return Fail(cmd, searcher.status());
  auto fp = ComputeEvaluationFingerprint(db_, *testset, input, options, tasks_);
  if (!fp.ok()) return Fail(cmd, fp.status());
  const std::vector<uint32_t> selected = SelectTestViews(*testset, options);
  auto points = MakeQueryPointsFn(input, db_);
  if (!points.ok()) return Fail(cmd, points.status());

  if (merge) {
    EvaluationReport report = StartReport((*searcher)->database(), *testset, input, options);
    Status s = MergeParts(work_, *fp, selected, &report);
    if (!s.ok()) return Fail(cmd, s);
    const std::string text = ReportToText(report);
    SlurmEvaluateLayout layout;
    layout.work_dir = work_;
    if (!json_out_.empty()) {
      const json doc = ReportToJson(report);
      s = ValidateJson(doc, "evaluation.schema.json", json_out_);
      if (s.ok()) s = WriteJsonFileAtomic(json_out_, doc);
      if (!s.ok()) return Fail(cmd, s);
    }
    if (!plots_dir_.empty()) {
      s = WriteReportPlots(report, **searcher, *testset, plots_dir_, *points);
      if (!s.ok()) return Fail(cmd, s);
    }
    // Last: its presence tells `handdb evaluate --slurm --wait` that the merge succeeded.
    s = WriteFileAtomic(layout.report_text(), text);
    if (!s.ok()) return Fail(cmd, s);
    if (!quiet_) std::printf("%s", text.c_str());
    return kExitOk;
  }

  PartExpectation expect;
  expect.fingerprint = *fp;
  expect.task = task_;
  expect.slice = TaskSlice(selected, task_, tasks_);
  expect.num_criteria = MakeCriteria(options).size();
  const fs::path path = PartPath(work_, task_);
  if (auto existing = ReadPart(path, expect); existing.ok()) {
    std::printf("task %u: %s already complete (%zu views); kept\n",
                task_,
                path.c_str(),
                existing->views.size());
    return kExitOk;
  }
  EvaluationPart part;
  part.fingerprint = *fp;
  part.task = task_;
  part.num_tasks = tasks_;
  part.threads = ResolveThreadCount(options.num_threads);
  part.started_at = UnixNow();
  auto views = EvaluateViews(**searcher, *testset, *points, options, expect.slice);
  if (!views.ok()) return Fail(cmd, views.status());
  part.views = std::move(*views);
  part.finished_at = UnixNow();
  Status s = WritePart(path, part);
  if (!s.ok()) return Fail(cmd, s);
  std::printf("task %u: %zu test views in %.1f s -> %s\n",
              task_,
              part.views.size(),
              part.finished_at - part.started_at,
              path.c_str());
  return kExitOk;
}

}  // namespace handdb::cli
