// `handdb evaluate --slurm` and the two worker commands its jobs run, `handdb unit evaluate` (one
// array task: one slice of the test views -> WORK/parts/part-0000T.json) and
// `handdb unit evaluate-merge` (the final job: parts -> the report of a local run).
// docs/cluster.md.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <nlohmann/json.hpp>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/thread_pool.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/evaluate_cli.h"
#include "cli/slurm_cli.h"
#include "cluster/slurm.h"
#include "evaluate/parts.h"
#include "query/searcher.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr uint32_t kItemsPerTask = 16;  // default split: tasks of a few seconds to minutes
constexpr uint32_t kMaxDefaultTasks = 1000;

// One line per task of `sub` without a complete part: "task 3: <reason>; log: <path>".
std::vector<std::string> TaskFailures(const SlurmEvaluateLayout& layout,
                                      const SlurmSubmission& sub,
                                      const std::vector<bool>& complete,
                                      const std::vector<SlurmJobState>& jobs) {
  std::vector<std::string> lines;
  for (const UnitFailure& f : CollectFailures(layout.Files(), "part", sub, complete, jobs)) {
    lines.push_back("task " + std::to_string(f.unit) + ": " + f.reason +
                    "; log: " + f.log.string());
  }
  return lines;
}

// The merge job's own one-line error ("handdb <merge_command>: ..."), if its log has one.
std::string MergeError(const SlurmEvaluateLayout& layout, const std::string& merge_command) {
  const std::string prefix = "handdb " + merge_command + ": ";
  const std::string log = ReadTrimmed(layout.Files().final_log());
  std::string found;
  size_t pos = 0;
  while (pos < log.size()) {
    size_t end = log.find('\n', pos);
    if (end == std::string::npos) end = log.size();
    const std::string line = log.substr(pos, end - pos);
    if (line.rfind(prefix, 0) == 0) found = line;
    pos = end + 1;
  }
  return found;
}

// The test-set parts of WORK (CompleteParts).
Result<std::vector<bool>> CompleteTestSetParts(const fs::path& work,
                                               const EvaluationFingerprint& fp,
                                               const std::vector<uint32_t>& selected,
                                               uint32_t num_tasks,
                                               size_t num_criteria) {
  return CompleteParts(num_tasks, [&](uint32_t t) {
    return ReadPart(PartPath(work, t), ExpectedPart(fp, t, selected, num_criteria)).status();
  });
}

// The files of an evaluation split into `tasks` parts and the words its jobs run: the same
// database, test set and options as this run, and its --json and --plots for the merge.
Result<SlurmEvaluateLayout> MakeEvaluateLayout(const EvaluateSlurmRequest& request,
                                               const TestSet& testset,
                                               const EvaluationFingerprint& fp,
                                               uint32_t tasks) {
  auto work =
      Absolute(request.work.empty() ? testset.dir / "slurm-evaluations" / fp.value : request.work);
  if (!work.ok()) return work.status();
  std::vector<std::string> common = {
      request.db, request.testset, "--tasks", std::to_string(tasks), "--work", work->string()};
  const auto eval_args = request.flags.Args();
  common.insert(common.end(), eval_args.begin(), eval_args.end());
  std::vector<std::string> task_args = {"unit", "evaluate"};
  task_args.insert(task_args.end(), common.begin(), common.end());
  std::vector<std::string> merge_args = {"unit", "evaluate-merge"};
  merge_args.insert(merge_args.end(), common.begin(), common.end());
  if (!request.json_out.empty()) merge_args.insert(merge_args.end(), {"--json", request.json_out});
  if (!request.plots_dir.empty()) {
    merge_args.insert(merge_args.end(), {"--plots", request.plots_dir});
  }
  return MakeSlurmEvaluateLayout(*work, std::move(task_args), std::move(merge_args));
}

// --wait: polls until every job has ended (finished tasks as progress), then reports the failed
// tasks or prints the merged report.
int WaitAndReport(const SlurmEvaluation& e,
                  const SlurmFlags& flags,
                  bool quiet,
                  const SlurmSubmission& sub,
                  const std::vector<uint32_t>& pending) {
  const char* cmd = "evaluate";
  const SlurmEvaluateLayout& layout = e.layout;
  auto states = WaitForJobs(sub, pending.size(), flags.poll_seconds, !quiet);
  if (!states.ok()) return Fail(cmd, states.status());
  auto after = e.complete_parts();
  if (!after.ok()) return Fail(cmd, after.status());
  const auto failures = TaskFailures(layout, sub, *after, *states);
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
    const std::string final_state = FinalJobState(sub, *states);
    const std::string why = MergeError(layout, e.merge_command);
    return Fail(cmd,
                Status(StatusCode::kExternalToolFailed,
                       "merge job " + sub.final_job_id + " ended " + final_state +
                           " without a report" + (why.empty() ? "" : " (" + why + ")") +
                           "; log: " + layout.Files().final_log().string()));
  }
  if (!quiet) std::printf("%s", report->c_str());
  return kExitOk;
}

}  // namespace

Result<std::vector<bool>> CompleteParts(uint32_t num_tasks,
                                        const std::function<Status(uint32_t)>& read_part) {
  std::vector<bool> complete(num_tasks, false);
  for (uint32_t t = 0; t < num_tasks; ++t) {
    const Status s = read_part(t);
    // A part of another evaluation is refused (it would be overwritten); anything else that is
    // not a complete part (absent, unreadable, truncated) is work for the part's task.
    if (s.ok()) {
      complete[t] = true;
    } else if (s.code() == StatusCode::kInvalidArgument) {
      return s;
    }
  }
  return complete;
}

Result<SlurmEvaluateLayout> MakeSlurmEvaluateLayout(const fs::path& work,
                                                    std::vector<std::string> task_args,
                                                    std::vector<std::string> merge_args) {
  SlurmEvaluateLayout layout;
  auto exe = SelfExecutable();
  if (!exe.ok()) return exe.status();
  layout.handdb = *exe;
  std::error_code ec;
  layout.submit_dir = fs::current_path(ec);
  if (ec) return Status(StatusCode::kIoError, "current directory: " + ec.message());
  auto abs = Absolute(work);
  if (!abs.ok()) return abs.status();
  layout.work_dir = *abs;
  layout.task_args = std::move(task_args);
  layout.merge_args = std::move(merge_args);
  return layout;
}

double UnixNow() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

uint32_t DefaultEvaluationTasks(uint32_t items) {
  return std::min(kMaxDefaultTasks, (items + kItemsPerTask - 1) / kItemsPerTask);
}

int SubmitSlurmEvaluation(const SlurmEvaluation& e, const SlurmFlags& flags, bool quiet) {
  const char* cmd = "evaluate";
  auto options = OptionsFromFlags(flags);
  if (!options.ok()) return Fail(cmd, options.status());
  const SlurmEvaluateLayout& layout = e.layout;

  // An earlier submission still running must end first (two tasks on one part do the work twice).
  PreviousSubmission previous;
  if (!flags.dry_run) {
    auto prev = CheckPreviousSubmission(layout.Files().jobs_file(),
                                        "of this evaluation (" + layout.work_dir.string() + ")");
    if (!prev.ok()) return Fail(cmd, prev.status());
    previous = std::move(*prev);
  }

  auto complete = e.complete_parts();
  if (!complete.ok()) return Fail(cmd, complete.status());
  const auto pending =
      PendingUnits(e.tasks, [&](uint32_t t) { return static_cast<bool>((*complete)[t]); });
  if (previous.exists) {
    for (const auto& line : TaskFailures(layout, previous.sub, *complete, previous.states)) {
      std::fprintf(stderr, "handdb %s: earlier Slurm run: %s\n", cmd, line.c_str());
    }
  }

  const SlurmArrayJob job = layout.Job();
  const SlurmArrayLayout& files = job.layout;
  std::error_code ec;
  const fs::path parts_dir = PartPath(layout.work_dir, 0).parent_path();
  fs::create_directories(parts_dir, ec);
  if (ec) {
    return Fail(
        cmd, Status(StatusCode::kIoError, parts_dir.string() + ": cannot create: " + ec.message()));
  }
  Status s = WriteJobScripts(job, *options);
  if (!s.ok()) return Fail(cmd, s);
  if (!flags.dry_run) {
    auto max_array = QueryMaxArraySize();
    if (!max_array.ok()) return Fail(cmd, max_array.status());
    options->max_array_size = *max_array;
    // Markers of tasks about to be resubmitted describe an old attempt; a report of an old merge
    // must not pass for the new one.
    for (uint32_t t : pending) fs::remove(files.TaskFailedMarker(t), ec);
    fs::remove(layout.report_text(), ec);
  }
  auto sub =
      SubmitArrayWithFinal(files, layout.work_dir.string(), *options, pending, flags.dry_run);
  if (!sub.ok()) return Fail(cmd, sub.status());

  const std::string tasks_text = pending.empty() ? "none" : FormatArrayRanges(pending);
  if (flags.dry_run) {
    std::printf(
        "dry run: %u %s in %u tasks, %zu to run (%s); work directory %s; scripts:\n"
        "  %s\n  %s\nwould run:\n",
        e.num_items,
        e.items_noun.c_str(),
        e.tasks,
        pending.size(),
        tasks_text.c_str(),
        layout.work_dir.c_str(),
        files.array_script().c_str(),
        files.final_script().c_str());
    for (const auto& c : sub->sbatch_commands) std::printf("  %s\n", FormatCommand(c).c_str());
    return kExitOk;
  }
  if (!quiet) {
    std::fprintf(stderr,
                 "handdb %s: submitted %zu of %u tasks (%s) as array job%s %s, merge job %s; "
                 "work directory %s\n",
                 cmd,
                 pending.size(),
                 e.tasks,
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
  return WaitAndReport(e, flags, quiet, *sub, pending);
}

int RunEvaluateOnSlurm(const EvaluateSlurmRequest& request, const SlurmFlags& flags) {
  const char* cmd = "evaluate";
  if (auto options = OptionsFromFlags(flags); !options.ok()) return Fail(cmd, options.status());
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
  const uint32_t tasks = request.tasks == 0 ? DefaultEvaluationTasks(num_selected) : request.tasks;
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
  auto layout = MakeEvaluateLayout(request, *testset, *fp, tasks);
  if (!layout.ok()) return Fail(cmd, layout.status());

  SlurmEvaluation e;
  e.layout = std::move(*layout);
  e.items_noun = "test views";
  e.num_items = num_selected;
  e.tasks = tasks;
  e.merge_command = "unit evaluate-merge";
  const size_t num_criteria = MakeCriteria(eval).size();
  e.complete_parts = [work = e.layout.work_dir, fp = *fp, selected, tasks, num_criteria] {
    return CompleteTestSetParts(work, fp, selected, tasks, num_criteria);
  };
  return SubmitSlurmEvaluation(e, flags, request.quiet);
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
  if (!flags_.Finish(cmd_name, quiet_)) return flags_.failure_exit_code;
  EvaluationOptions& options = flags_.options;
  if (!merge && options.num_threads == -1) options.num_threads = TaskThreads();
  if (!merge && task_ >= tasks_) {
    std::fprintf(stderr, "handdb %s: --task %u: must be below --tasks %u\n", cmd, task_, tasks_);
    return kExitUsage;
  }
  const QueryInput input = flags_.query_input();
  auto testset = ReadTestSet(testset_);
  if (!testset.ok()) return Fail(cmd, testset.status());
  auto searcher = Searcher::Open(db_, flags_.searcher_options());
  if (!searcher.ok()) return Fail(cmd, searcher.status());
  if (!merge && !flags_.LoadFit(db_, cmd_name)) return kExitError;
  auto fp = ComputeEvaluationFingerprint(db_, *testset, input, options, tasks_);
  if (!fp.ok()) return Fail(cmd, fp.status());
  const std::vector<uint32_t> selected = SelectTestViews(*testset, options);
  auto points = MakeQueryPointsFn(input, db_, (*searcher)->database(), flags_.landmarker);
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

  const auto expect = ExpectedPart(*fp, task_, selected, MakeCriteria(options).size());
  const fs::path path = PartPath(work_, task_);
  if (auto existing = ReadPart(path, expect); existing.ok()) {
    std::printf("task %u: %s already complete (%zu views); kept\n",
                task_,
                path.c_str(),
                existing->rows.size());
    return kExitOk;
  }
  EvaluationPart part;
  part.fingerprint = *fp;
  part.task = task_;
  part.num_tasks = tasks_;
  part.threads = ResolveNumThreads(options.num_threads);
  part.started_at = UnixNow();
  auto views = EvaluateViews(**searcher, *testset, *points, options, expect.rows.slice);
  if (!views.ok()) return Fail(cmd, views.status());
  part.rows = std::move(*views);
  part.finished_at = UnixNow();
  Status s = WritePart(path, part);
  if (!s.ok()) return Fail(cmd, s);
  std::printf("task %u: %zu test views in %.1f s -> %s\n",
              task_,
              part.rows.size(),
              part.finished_at - part.started_at,
              path.c_str());
  return kExitOk;
}

}  // namespace handdb::cli
