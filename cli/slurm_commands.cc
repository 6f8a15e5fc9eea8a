// `handdb unit render|convert|finalize|status` (the per-unit work a Slurm array task does) and the
// `--slurm` path of `handdb generate` (docs/cluster.md).
#include "cli/slurm_commands.h"

#include <cstdio>
#include <nlohmann/json.hpp>

#include "base/atomic_file.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/evaluate_cli.h"
#include "cli/slurm_cli.h"
#include "cluster/slurm.h"
#include "format/manifest.h"
#include "format/validator.h"
#include "generator/plan/plan.h"
#include "generator/render/render_driver.h"
#include "query/index/database_index.h"
#include "query/index/view_index.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// The edge options, --skip-bad and --coded of `handdb unit convert|finalize|status`, spelled as in
// `handdb generate`, which passes its own on verbatim.
struct ConvertFlags {
  EdgeFlags edges;
  bool skip_bad = false;
  bool coded = false;
  void Add(CLI::App& app) {
    edges.Add(app, "depth difference that makes a joint-pair border an occlusion edge");
    app.add_flag("--skip-bad", skip_bad, "leave bad views out instead of failing");
    app.add_flag(
        "--coded", coded, "write coded shards (format v1.2), as `handdb generate --coded`");
  }
  ConvertOptions Get(int threads, bool progress) const {
    ConvertOptions o;
    o.edges = edges.Get();
    o.skip_bad = skip_bad;
    o.coded = coded;
    o.num_threads = threads;
    o.progress = progress;
    return o;
  }
};

// Why each unit of `sub` without a complete shard failed.
std::vector<UnitFailure> CollectFailures(const SlurmGenerateLayout& layout,
                                         const SlurmSubmission& sub,
                                         const std::vector<bool>& complete,
                                         const std::vector<SlurmJobState>& jobs) {
  return CollectFailures(layout.Files(), "shard", sub, complete, jobs);
}

json FailuresJson(const std::vector<UnitFailure>& failures) {
  json f = json::array();
  for (const auto& x : failures) {
    f.push_back({{"unit", x.unit}, {"reason", x.reason}, {"log", x.log.string()}});
  }
  return f;
}

constexpr const char* kGenerate = "generate";

// The paths of a Slurm generation, absolute, and the arguments its tasks pass on.
Result<SlurmGenerateLayout> MakeGenerateLayout(const SlurmGenerateRequest& request) {
  SlurmGenerateLayout layout;
  auto exe = SelfExecutable();
  if (!exe.ok()) return exe.status();
  layout.handdb = *exe;
  auto run_dir = Absolute(request.work_dir);
  if (!run_dir.ok()) return run_dir.status();
  layout.run_dir = *run_dir;
  auto db_dir = Absolute(request.db_dir);
  if (!db_dir.ok()) return db_dir.status();
  layout.db_dir = *db_dir;
  layout.slurm_dir = layout.run_dir / "slurm";
  if (!request.blender.empty()) {
    // A bare name is looked up on PATH on the compute node; a path must be absolute there.
    fs::path blender = request.blender;
    if (blender.has_parent_path()) {
      auto abs = Absolute(blender);
      if (!abs.ok()) return abs.status();
      blender = *abs;
    }
    layout.render_args = {"--blender", blender.string()};
  }
  layout.convert_args = request.convert_args;
  layout.build_index = request.build_index;
  return layout;
}

// Nothing to submit and the database validates: says so. False when there is work to submit.
bool ReportAlreadyComplete(const SlurmGenerateRequest& request,
                           const SlurmGenerateLayout& layout,
                           size_t num_units) {
  const ValidationReport report = ValidateDatabase(layout.db_dir, ValidateOptions{});
  if (!report.ok()) return false;
  if (request.build_index) {  // complete, but the index asked for is missing: the final job runs
    auto manifest = ReadManifest(layout.db_dir);
    if (!manifest.ok() || !manifest->index) return false;
  }
  if (request.as_json) {
    std::printf("%s\n",
                json({{"db", layout.db_dir.string()},
                      {"units", num_units},
                      {"submitted_units", json::array()},
                      {"complete", true}})
                    .dump(2)
                    .c_str());
  } else {
    std::printf("%s: all %zu units complete and the database validates; nothing to submit\n",
                layout.db_dir.string().c_str(),
                num_units);
  }
  return true;
}

void PrintDryRun(const SlurmGenerateRequest& request,
                 const SlurmGenerateLayout& layout,
                 const SlurmSubmission& sub,
                 const std::vector<uint32_t>& pending,
                 size_t num_units) {
  const SlurmArrayLayout files = layout.Files();
  if (request.as_json) {
    json cmds = json::array();
    for (const auto& c : sub.sbatch_commands) cmds.push_back(c);
    std::printf("%s\n",
                json({{"db", layout.db_dir.string()},
                      {"units", num_units},
                      {"submitted_units", pending},
                      {"array_script", files.array_script().string()},
                      {"final_script", files.final_script().string()},
                      {"sbatch_commands", cmds}})
                    .dump(2)
                    .c_str());
    return;
  }
  std::printf("dry run: %zu of %zu units to run (%s); scripts:\n  %s\n  %s\nwould run:\n",
              pending.size(),
              num_units,
              pending.empty() ? "none" : FormatArrayRanges(pending).c_str(),
              files.array_script().string().c_str(),
              files.final_script().string().c_str());
  for (const auto& c : sub.sbatch_commands) std::printf("  %s\n", FormatCommand(c).c_str());
}

void PrintSubmitted(const SlurmGenerateRequest& request,
                    const SlurmGenerateLayout& layout,
                    const SlurmSubmission& sub,
                    const std::vector<uint32_t>& pending,
                    size_t num_units) {
  if (request.as_json) {
    std::printf("%s\n",
                json({{"db", layout.db_dir.string()},
                      {"units", num_units},
                      {"submitted_units", pending},
                      {"array_job_ids", sub.array_job_ids},
                      {"final_job_id", sub.final_job_id},
                      {"logs", layout.Files().log_dir().string()}})
                    .dump(2)
                    .c_str());
  } else {
    std::printf(
        "submitted: array job(s) %s, final job %s. Run the same command again to see "
        "failures and resubmit only the missing units.\n",
        JoinIds(sub.array_job_ids).c_str(),
        sub.final_job_id.c_str());
  }
}

// --wait: polls Slurm until every job has ended, then reports failed units and the database.
int WaitAndReport(const SlurmGenerateRequest& request,
                  const SlurmGenerateLayout& layout,
                  const SlurmFlags& flags,
                  const SlurmSubmission& sub,
                  const std::vector<uint32_t>& pending) {
  const char* cmd = kGenerate;
  auto states = WaitForJobs(sub, pending.size(), flags.poll_seconds, !request.quiet);
  if (!states.ok()) return Fail(cmd, states.status());
  auto after = FindCompleteShards(layout.run_dir, layout.db_dir, request.convert);
  if (!after.ok()) return Fail(cmd, after.status());
  const auto failures = CollectFailures(layout, sub, *after, *states);
  for (const auto& f : failures) {
    std::fprintf(stderr, "handdb %s: %s\n", cmd, FormatUnitFailure(f).c_str());
  }
  const std::string final_state = FinalJobState(sub, *states);
  const ValidationReport report = ValidateDatabase(layout.db_dir, ValidateOptions{});
  const bool ok = failures.empty() && report.ok();
  if (request.as_json) {
    std::printf("%s\n",
                json({{"db", layout.db_dir.string()},
                      {"units", after->size()},
                      {"submitted_units", pending},
                      {"array_job_ids", sub.array_job_ids},
                      {"final_job_id", sub.final_job_id},
                      {"final_job_state", final_state},
                      {"failed", FailuresJson(failures)},
                      {"complete", ok},
                      {"validated_views", report.views}})
                    .dump(2)
                    .c_str());
  }
  if (!failures.empty()) {
    return Fail(cmd,
                Status(StatusCode::kExternalToolFailed,
                       std::to_string(failures.size()) + " of " + std::to_string(pending.size()) +
                           " Slurm tasks failed (listed above); run the same command again "
                           "to resubmit only the missing units"));
  }
  if (!report.ok()) {
    for (const auto& p : report.problems) {
      std::fprintf(stderr, "handdb %s: %s\n", cmd, p.message.c_str());
    }
    return Fail(cmd,
                Status(StatusCode::kSchemaViolation,
                       "final job " + sub.final_job_id + " ended " + final_state +
                           " but the database does not validate; log: " +
                           layout.Files().final_log().string()));
  }
  if (!request.as_json) {
    std::printf("%s: %zu units complete on Slurm, %llu views validated: ok\n",
                layout.db_dir.string().c_str(),
                after->size(),
                static_cast<unsigned long long>(report.views));
  }
  return kExitOk;
}

}  // namespace

int RunGenerateOnSlurm(const SlurmGenerateRequest& request, const SlurmFlags& flags) {
  const char* cmd = kGenerate;
  auto slurm_options = OptionsFromFlags(flags);
  if (!slurm_options.ok()) return Fail(cmd, slurm_options.status());
  SlurmOptions& options = *slurm_options;
  auto made = MakeGenerateLayout(request);
  if (!made.ok()) return Fail(cmd, made.status());
  const SlurmGenerateLayout& layout = *made;
  const SlurmArrayJob job = layout.Job();

  // A previous submission still running must finish (or be cancelled) first: two tasks on the
  // same unit would do the same work twice.
  PreviousSubmission previous;
  if (!flags.dry_run) {
    auto prev = CheckPreviousSubmission(job.layout.jobs_file(), "for " + layout.db_dir.string());
    if (!prev.ok()) return Fail(cmd, prev.status());
    previous = std::move(*prev);
  }

  auto complete = FindCompleteShards(layout.run_dir, layout.db_dir, request.convert);
  if (!complete.ok()) return Fail(cmd, complete.status());
  const auto pending = PendingUnits(static_cast<uint32_t>(complete->size()),
                                    [&](uint32_t u) { return (*complete)[u]; });
  // Failures are reported for the previous submission of this database only (RUN_DIR may be
  // shared by several databases through --work).
  if (previous.exists && previous.sub.db_dir == layout.db_dir.string()) {
    for (const auto& f : CollectFailures(layout, previous.sub, *complete, previous.states)) {
      std::fprintf(stderr, "handdb %s: earlier Slurm run: %s\n", cmd, FormatUnitFailure(f).c_str());
    }
  }
  if (pending.empty() && !flags.dry_run &&
      ReportAlreadyComplete(request, layout, complete->size())) {
    return kExitOk;
  }

  if (!flags.dry_run) {
    auto max_array = QueryMaxArraySize();
    if (!max_array.ok()) return Fail(cmd, max_array.status());
    options.max_array_size = *max_array;
  }
  // Failure markers of units about to be resubmitted describe an old attempt.
  std::error_code ec;
  for (uint32_t u : pending) fs::remove(job.layout.TaskFailedMarker(u), ec);
  fs::create_directories(layout.db_dir, ec);
  if (ec) {
    return Fail(
        cmd,
        Status(StatusCode::kIoError, layout.db_dir.string() + ": cannot create: " + ec.message()));
  }
  Status written = WriteJobScripts(job, options);
  if (!written.ok()) return Fail(cmd, written);
  auto sub =
      SubmitArrayWithFinal(job.layout, layout.db_dir.string(), options, pending, flags.dry_run);
  if (!sub.ok()) return Fail(cmd, sub.status());

  if (flags.dry_run) {
    PrintDryRun(request, layout, *sub, pending, complete->size());
    return kExitOk;
  }
  if (!request.quiet) {
    std::fprintf(stderr,
                 "handdb %s: submitted %zu of %zu units (%s) as array job%s %s, final job %s; "
                 "logs in %s\n",
                 cmd,
                 pending.size(),
                 complete->size(),
                 pending.empty() ? "none" : FormatArrayRanges(pending).c_str(),
                 sub->array_job_ids.size() == 1 ? "" : "s",
                 JoinIds(sub->array_job_ids).c_str(),
                 sub->final_job_id.c_str(),
                 job.layout.log_dir().string().c_str());
  }
  if (!flags.wait) {
    PrintSubmitted(request, layout, *sub, pending, complete->size());
    return kExitOk;
  }
  return WaitAndReport(request, layout, flags, *sub, pending);
}

// ---- handdb unit --------------------------------------------------------------------------------

namespace {

// What the `handdb unit` subcommands parse (each uses its share).
struct UnitArgs {
  fs::path plan_path, run_dir, db_dir, blender;
  int64_t unit = -1;
  int threads = 0;
  ConvertFlags convert;
  bool build_index = false;  // unit finalize --index
  bool quiet = false;
  bool as_json = false;
};

int RunUnitRender(const UnitArgs& args) {
  const std::string cmd = "unit render";
  RenderOptions options;
  options.jobs = 1;
  options.blender = args.blender;
  options.units = {static_cast<uint32_t>(args.unit)};
  options.progress = !args.quiet;
  auto plan = ReadPlan(args.plan_path);
  if (!plan.ok()) return Fail(cmd, plan.status());
  if (static_cast<uint64_t>(args.unit) >= plan->units.size()) {
    return Fail(cmd,
                Status(StatusCode::kOutOfRange,
                       args.plan_path.string() + ": no unit " + std::to_string(args.unit) +
                           " (the plan has " + std::to_string(plan->units.size()) + ")"));
  }
  auto summary = RenderPlan(args.plan_path, args.run_dir, options);
  if (!summary.ok()) {
    // Exit 1 even when interrupted: the array script records the exit code in the task's marker.
    PrintError(cmd, summary.status());
    return kExitError;
  }
  std::printf("unit %lld: %llu renders (%s) in %.1f s\n",
              static_cast<long long>(args.unit),
              static_cast<unsigned long long>(summary->renders_done),
              summary->units_skipped > 0 ? "already done" : "rendered",
              summary->seconds);
  return kExitOk;
}

int RunUnitConvert(const UnitArgs& args) {
  const std::string cmd = "unit convert";
  ConvertOptions options = args.convert.Get(args.threads, !args.quiet);
  options.units = {static_cast<uint32_t>(args.unit)};
  std::vector<SkippedView> bad;
  auto summary = ConvertRenderDir(args.run_dir, args.db_dir, options, &bad);
  if (!summary.ok()) {
    for (const auto& b : bad) {
      std::fprintf(stderr,
                   "handdb %s: %s: %s\n",
                   cmd.c_str(),
                   (args.run_dir / b.file).c_str(),
                   b.reason.c_str());
    }
    return Fail(cmd, summary.status());
  }
  std::printf("unit %lld: shard %s (%llu views, %llu bytes, %zu skipped) in %.1f s\n",
              static_cast<long long>(args.unit),
              summary->shards_kept > 0 ? "kept" : "written",
              static_cast<unsigned long long>(summary->views),
              static_cast<unsigned long long>(summary->bytes),
              summary->skipped.size(),
              summary->seconds);
  return kExitOk;
}

int RunUnitFinalize(const UnitArgs& args) {
  const std::string cmd = "unit finalize";
  const fs::path& db_dir = args.db_dir;
  const ConvertOptions options = args.convert.Get(args.threads, !args.quiet);
  auto complete = FindCompleteShards(args.run_dir, db_dir, options);
  if (!complete.ok()) return Fail(cmd, complete.status());
  const auto missing = PendingUnits(static_cast<uint32_t>(complete->size()),
                                    [&](uint32_t u) { return (*complete)[u]; });
  if (!missing.empty()) {
    return Fail(cmd,
                Status(StatusCode::kNotFound,
                       db_dir.string() + ": " + std::to_string(missing.size()) +
                           " units have no complete shard yet (" + FormatArrayRanges(missing) +
                           "); run their tasks first"));
  }
  auto summary = ConvertRenderDir(args.run_dir, db_dir, options);
  if (!summary.ok()) return Fail(cmd, summary.status());
  ValidateOptions vopt;
  vopt.show_progress = !args.quiet;
  const ValidationReport report = ValidateDatabase(db_dir, vopt);
  if (!report.ok()) {
    for (const auto& p : report.problems) {
      std::fprintf(stderr, "handdb %s: %s\n", cmd.c_str(), p.message.c_str());
    }
    return Fail(cmd,
                Status(StatusCode::kSchemaViolation,
                       db_dir.string() + ": validation found " +
                           std::to_string(report.num_problems()) + " problem(s)"));
  }
  // --index (generate --slurm --index): as `handdb index DB` does. No lock here, as for the
  // manifest above: the submitting `generate --wait` may hold DB's lock while this job runs.
  if (args.build_index) {
    IndexBuildOptions index_options;
    index_options.num_threads = args.threads > 0 ? args.threads : TaskThreads();
    index_options.progress = !args.quiet;
    if (auto written = WriteDatabaseIndex(db_dir, index_options); !written.ok()) {
      return Fail(cmd, written.status());
    }
  }
  if (args.as_json) {
    std::printf("%s\n",
                json({{"db", db_dir.string()},
                      {"units", summary->units_total},
                      {"views", summary->views},
                      {"virtual_views", summary->views * summary->rolls},
                      {"bytes", summary->bytes},
                      {"validated_views", report.views}})
                    .dump(2)
                    .c_str());
  } else {
    std::printf("%s: manifest written, %u shards, %llu views validated: ok\n",
                db_dir.string().c_str(),
                summary->units_total,
                static_cast<unsigned long long>(report.views));
  }
  return kExitOk;
}

int RunUnitStatus(const UnitArgs& args) {
  const std::string cmd = "unit status";
  auto complete = FindCompleteShards(args.run_dir, args.db_dir, args.convert.Get(1, false));
  if (!complete.ok()) return Fail(cmd, complete.status());
  const auto pending = PendingUnits(static_cast<uint32_t>(complete->size()),
                                    [&](uint32_t u) { return (*complete)[u]; });
  SlurmGenerateLayout layout;
  layout.run_dir = args.run_dir;
  layout.db_dir = args.db_dir;
  layout.slurm_dir = args.run_dir / "slurm";
  const fs::path jobs_file = layout.Files().jobs_file();
  std::vector<UnitFailure> failures;
  std::error_code ec;
  if (fs::exists(jobs_file, ec)) {
    auto sub = ReadSubmissionRecord(jobs_file);
    if (!sub.ok()) return Fail(cmd, sub.status());
    auto abs_db = Absolute(args.db_dir);
    if (abs_db.ok() && sub->db_dir == abs_db->string()) {
      // Without Slurm commands (e.g. on a login node without them) the markers still tell.
      auto jobs = QueryJobs(JobIds(*sub));
      failures = CollectFailures(
          layout, *sub, *complete, jobs.ok() ? *jobs : std::vector<SlurmJobState>{});
    }
  }
  if (args.as_json) {
    std::printf("%s\n",
                json({{"units", complete->size()},
                      {"complete", complete->size() - pending.size()},
                      {"pending", pending},
                      {"failed", FailuresJson(failures)}})
                    .dump(2)
                    .c_str());
  } else {
    std::printf("%zu of %zu units complete; pending: %s\n",
                complete->size() - pending.size(),
                complete->size(),
                pending.empty() ? "none" : FormatArrayRanges(pending).c_str());
    for (const auto& f : failures) std::printf("%s\n", FormatUnitFailure(f).c_str());
  }
  return kExitOk;
}

}  // namespace

int RunUnit(int argc, char** argv) {
  CLI::App app(
      "Per-unit work, as run by the Slurm array tasks of `handdb generate --slurm` (one task = one "
      "render unit) and `handdb evaluate --slurm` (one task = one slice of the test views or of "
      "the photos). Every subcommand is idempotent: finished renders, complete shards and parts "
      "are kept.",
      "handdb unit");
  app.require_subcommand(1);
  UnitArgs args;

  auto* render = app.add_subcommand("render", "render one unit of a plan with Blender");
  render->add_option("PLAN", args.plan_path, "plan.json")->required();
  render->add_option("--unit", args.unit, "unit id")->required()->check(CLI::NonNegativeNumber);
  render->add_option("--out,-o", args.run_dir, "render directory (RUN_DIR)")->required();
  render->add_option(
      "--blender", args.blender, "Blender executable (default: $HANDDB_BLENDER or PATH)");
  render->add_flag("--quiet,-q", args.quiet, "no progress display");

  auto* convert = app.add_subcommand("convert", "convert one rendered unit into its shard");
  convert->add_option("RUN_DIR", args.run_dir, "render directory (plan.json, units/)")->required();
  convert->add_option("--unit", args.unit, "unit id")->required()->check(CLI::NonNegativeNumber);
  convert->add_option("--out,-o", args.db_dir, "database directory")->required();
  convert->add_option("--threads,-j", args.threads, "threads (default: $SLURM_CPUS_PER_TASK or 1)")
      ->check(CLI::PositiveNumber);
  args.convert.Add(*convert);
  convert->add_flag("--quiet,-q", args.quiet, "no progress display");

  auto* finalize = app.add_subcommand(
      "finalize", "write the manifest once every shard is complete, then validate the database");
  finalize->add_option("RUN_DIR", args.run_dir, "render directory (plan.json, units/)")->required();
  finalize->add_option("--out,-o", args.db_dir, "database directory")->required();
  finalize->add_option("--threads,-j", args.threads, "threads (default: $SLURM_CPUS_PER_TASK or 1)")
      ->check(CLI::PositiveNumber);
  args.convert.Add(*finalize);
  finalize->add_flag("--index", args.build_index, "then build the search index (handdb index DB)");
  finalize->add_flag("--quiet,-q", args.quiet, "no progress display");
  finalize->add_flag("--json", args.as_json, "print the summary as JSON on stdout");

  auto* status = app.add_subcommand(
      "status", "which units have a complete shard; why the others failed on Slurm");
  status->add_option("RUN_DIR", args.run_dir, "render directory (plan.json, units/)")->required();
  status->add_option("--out,-o", args.db_dir, "database directory")->required();
  args.convert.Add(*status);
  status->add_flag("--json", args.as_json, "print the status as JSON on stdout");

  // unit evaluate | evaluate-merge: the tasks of `handdb evaluate --slurm`; unit evaluate-photos |
  // evaluate-photos-merge: those of `handdb evaluate --photos DIR --slurm`.
  UnitEvaluateCommands evaluate_commands(app);
  UnitEvaluatePhotosCommands evaluate_photos_commands(app);

  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  if (evaluate_commands.parsed()) return evaluate_commands.Run();
  if (evaluate_photos_commands.parsed()) return evaluate_photos_commands.Run();
  if (args.threads <= 0) args.threads = TaskThreads();
  if (render->parsed()) return RunUnitRender(args);
  if (convert->parsed()) return RunUnitConvert(args);
  if (finalize->parsed()) return RunUnitFinalize(args);
  return RunUnitStatus(args);
}

}  // namespace handdb::cli
