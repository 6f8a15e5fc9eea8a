// `handdb unit render|convert|finalize|status` (the per-unit work a Slurm array task does) and the
// `--slurm` path of `handdb generate` (issue 7, docs/cluster.md).
#include "cli/slurm_commands.h"

#include <cstdio>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "cli/evaluate_cli.h"
#include "cli/slurm_cli.h"
#include "base/atomic_file.h"
#include "format/manifest.h"
#include "format/validator.h"
#include "generator/plan/plan.h"
#include "generator/render/render_driver.h"
#include "cluster/slurm.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

int Fail(const std::string& cmd, const Status& status) {
  std::fprintf(stderr, "handdb %s: %s\n", cmd.c_str(), status.message().c_str());
  return kExitError;
}

// The edge options and --skip-bad, spelled as in `handdb convert` / `handdb generate`.
struct ConvertFlags {
  std::string occlusion = "on";
  double depth_jump = EdgeOptions{}.depth_jump;
  bool skip_bad = false;
  void Add(CLI::App& app) {
    app.add_option("--occlusion-edges",
                   occlusion,
                   "keep joint-pair borders across a depth jump as occlusion edges (on|off)")
        ->check(CLI::IsMember({"on", "off"}))
        ->capture_default_str();
    app.add_option("--depth-jump",
                   depth_jump,
                   "depth difference that makes a joint-pair border an occlusion edge")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    app.add_flag("--skip-bad", skip_bad, "leave bad views out instead of failing");
  }
  ConvertOptions Get(int threads, bool progress) const {
    ConvertOptions o;
    o.edges.occlusion_edges = occlusion == "on";
    o.edges.depth_jump = depth_jump;
    o.skip_bad = skip_bad;
    o.num_threads = threads;
    o.progress = progress;
    return o;
  }
};

std::string FormatDouble(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

// Units of the plan in RUN_DIR whose shard in DB_DIR is complete, as a rerun of convert sees them.
Result<std::vector<bool>> CompleteUnits(const fs::path& run_dir,
                                        const fs::path& db_dir,
                                        const ConvertOptions& options) {
  return FindCompleteShards(run_dir, db_dir, options);
}

// ---- failure reports ---------------------------------------------------------------------------

// Why each unit of `sub` without a complete shard failed.
std::vector<UnitFailure> CollectFailures(const SlurmGenerateLayout& layout,
                                         const SlurmSubmission& sub,
                                         const std::vector<bool>& complete,
                                         const std::vector<SlurmJobState>& jobs) {
  const TaskFiles files{[&](uint32_t u) { return layout.UnitLog(u); },
                        [&](uint32_t u) { return layout.UnitFailedMarker(u); },
                        layout.log_dir(),
                        "shard"};
  return cli::CollectFailures(files, sub, complete, jobs);
}

}  // namespace

std::vector<std::string> ConvertArgs(const EdgeOptions& edges, bool skip_bad) {
  std::vector<std::string> args = {"--occlusion-edges",
                                   edges.occlusion_edges ? "on" : "off",
                                   "--depth-jump",
                                   FormatDouble(edges.depth_jump)};
  if (skip_bad) args.push_back("--skip-bad");
  return args;
}

void SlurmFlags::Add(CLI::App& app) {
  const char* group = "Slurm (docs/cluster.md)";
  app.add_flag(
         "--slurm", enabled, "run on a Slurm cluster: one array task per unit, then a final job")
      ->group(group);
  app.add_option("--partition", partition, "Slurm partition (default: the cluster's)")
      ->group(group);
  app.add_option(
         "--max-parallel", max_parallel, "at most N array tasks at once (default: no limit)")
      ->check(CLI::PositiveNumber)
      ->group(group);
  app.add_option("--time", time, "time limit of each task, Slurm syntax (e.g. 1:00:00)")
      ->group(group);
  app.add_option("--mem", mem, "memory of each task, e.g. 2G (default: the cluster's)")
      ->group(group);
  app.add_option("--cpus-per-task", cpus_per_task, "CPUs of each task")
      ->check(CLI::PositiveNumber)
      ->capture_default_str()
      ->group(group);
  app.add_option("--slurm-setup",
                 setup_file,
                 "file of shell lines every job runs first (module load, PATH=...)")
      ->check(CLI::ExistingFile)
      ->group(group);
  app.add_option("--sbatch-arg", sbatch_args, "extra sbatch option, verbatim (repeatable)")
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

int RunGenerateOnSlurm(const SlurmGenerateRequest& request, const SlurmFlags& flags) {
  const std::string cmd = "generate";
  auto slurm_options = OptionsFromFlags(flags);
  if (!slurm_options.ok()) return Fail(cmd, slurm_options.status());
  SlurmOptions& options = *slurm_options;

  SlurmGenerateLayout layout;
  {
    auto exe = SelfExecutable();
    if (!exe.ok()) return Fail(cmd, exe.status());
    layout.handdb = *exe;
    auto run_dir = Absolute(request.work_dir);
    if (!run_dir.ok()) return Fail(cmd, run_dir.status());
    layout.run_dir = *run_dir;
    auto db_dir = Absolute(request.db_dir);
    if (!db_dir.ok()) return Fail(cmd, db_dir.status());
    layout.db_dir = *db_dir;
  }
  layout.slurm_dir = layout.run_dir / "slurm";
  if (!request.blender.empty()) {
    // A bare name is looked up on PATH on the compute node; a path must be absolute there.
    fs::path blender = request.blender;
    if (blender.has_parent_path()) {
      auto abs = Absolute(blender);
      if (!abs.ok()) return Fail(cmd, abs.status());
      blender = *abs;
    }
    layout.render_args = {"--blender", blender.string()};
  }
  layout.convert_args = ConvertArgs(request.convert.edges, request.convert.skip_bad);

  // A previous submission still running must finish (or be cancelled) first: two tasks on the
  // same unit would do the same work twice.
  PreviousSubmission previous;
  if (!flags.dry_run) {
    auto prev = CheckPreviousSubmission(layout.jobs_file(), "for " + layout.db_dir.string());
    if (!prev.ok()) return Fail(cmd, prev.status());
    previous = std::move(*prev);
  }

  auto complete = CompleteUnits(layout.run_dir, layout.db_dir, request.convert);
  if (!complete.ok()) return Fail(cmd, complete.status());
  const auto pending = PendingUnits(static_cast<uint32_t>(complete->size()),
                                    [&](uint32_t u) { return (*complete)[u]; });
  // Failures are reported for the previous submission of this database only (RUN_DIR may be
  // shared by several databases through --work).
  if (previous.exists && previous.sub.db_dir == layout.db_dir.string()) {
    for (const auto& f : CollectFailures(layout, previous.sub, *complete, previous.states)) {
      std::fprintf(
          stderr, "handdb %s: earlier Slurm run: %s\n", cmd.c_str(), FormatUnitFailure(f).c_str());
    }
  }
  if (pending.empty() && !flags.dry_run) {
    const ValidationReport report = ValidateDatabase(layout.db_dir, ValidateOptions{});
    if (report.ok()) {
      if (request.as_json) {
        std::printf("%s\n",
                    json({{"db", layout.db_dir.string()},
                          {"units", complete->size()},
                          {"submitted_units", json::array()},
                          {"complete", true}})
                        .dump(2)
                        .c_str());
      } else {
        std::printf("%s: all %zu units complete and the database validates; nothing to submit\n",
                    layout.db_dir.string().c_str(),
                    complete->size());
      }
      return kExitOk;
    }
  }

  if (!flags.dry_run) {
    auto max_array = QueryMaxArraySize();
    if (!max_array.ok()) return Fail(cmd, max_array.status());
    options.max_array_size = *max_array;
  }
  // Failure markers of units about to be resubmitted describe an old attempt.
  std::error_code ec;
  for (uint32_t u : pending) fs::remove(layout.UnitFailedMarker(u), ec);
  auto sub = SubmitGenerateJobs(layout, options, pending, flags.dry_run);
  if (!sub.ok()) return Fail(cmd, sub.status());

  const std::string units_text = pending.empty() ? "none" : FormatArrayRanges(pending);
  if (flags.dry_run) {
    if (request.as_json) {
      json cmds = json::array();
      for (const auto& c : sub->sbatch_commands) cmds.push_back(c);
      std::printf("%s\n",
                  json({{"db", layout.db_dir.string()},
                        {"units", complete->size()},
                        {"submitted_units", pending},
                        {"array_script", layout.array_script().string()},
                        {"final_script", layout.final_script().string()},
                        {"sbatch_commands", cmds}})
                      .dump(2)
                      .c_str());
    } else {
      std::printf("dry run: %zu of %zu units to run (%s); scripts:\n  %s\n  %s\nwould run:\n",
                  pending.size(),
                  complete->size(),
                  units_text.c_str(),
                  layout.array_script().string().c_str(),
                  layout.final_script().string().c_str());
      for (const auto& c : sub->sbatch_commands) {
        std::printf("  %s\n", FormatCommand(c).c_str());
      }
    }
    return kExitOk;
  }
  if (!request.quiet) {
    std::fprintf(stderr,
                 "handdb %s: submitted %zu of %zu units (%s) as array job%s %s, final job %s; "
                 "logs in %s\n",
                 cmd.c_str(),
                 pending.size(),
                 complete->size(),
                 units_text.c_str(),
                 sub->array_job_ids.size() == 1 ? "" : "s",
                 JoinIds(sub->array_job_ids).c_str(),
                 sub->final_job_id.c_str(),
                 layout.log_dir().string().c_str());
  }
  if (!flags.wait) {
    if (request.as_json) {
      std::printf("%s\n",
                  json({{"db", layout.db_dir.string()},
                        {"units", complete->size()},
                        {"submitted_units", pending},
                        {"array_job_ids", sub->array_job_ids},
                        {"final_job_id", sub->final_job_id},
                        {"logs", layout.log_dir().string()}})
                      .dump(2)
                      .c_str());
    } else {
      std::printf(
          "submitted: array job(s) %s, final job %s. Run the same command again to see "
          "failures and resubmit only the missing units.\n",
          JoinIds(sub->array_job_ids).c_str(),
          sub->final_job_id.c_str());
    }
    return kExitOk;
  }

  // --wait: poll Slurm until every job has ended, showing finished tasks as progress.
  auto states = WaitForJobs(*sub, pending.size(), flags.poll_seconds, !request.quiet);
  if (!states.ok()) return Fail(cmd, states.status());
  auto after = CompleteUnits(layout.run_dir, layout.db_dir, request.convert);
  if (!after.ok()) return Fail(cmd, after.status());
  const auto failures = CollectFailures(layout, *sub, *after, *states);
  for (const auto& f : failures) {
    std::fprintf(stderr, "handdb %s: %s\n", cmd.c_str(), FormatUnitFailure(f).c_str());
  }
  const std::string final_state = FinalJobState(*sub, *states);
  const ValidationReport report = ValidateDatabase(layout.db_dir, ValidateOptions{});
  const bool ok = failures.empty() && report.ok();
  if (request.as_json) {
    json f = json::array();
    for (const auto& x : failures) {
      f.push_back({{"unit", x.unit}, {"reason", x.reason}, {"log", x.log.string()}});
    }
    std::printf("%s\n",
                json({{"db", layout.db_dir.string()},
                      {"units", after->size()},
                      {"submitted_units", pending},
                      {"array_job_ids", sub->array_job_ids},
                      {"final_job_id", sub->final_job_id},
                      {"final_job_state", final_state},
                      {"failed", f},
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
      std::fprintf(stderr, "handdb %s: %s\n", cmd.c_str(), p.message.c_str());
    }
    return Fail(
        cmd,
        Status(StatusCode::kSchemaViolation,
               "final job " + sub->final_job_id + " ended " + final_state +
                   " but the database does not validate; log: " + layout.final_log().string()));
  }
  if (!request.as_json) {
    std::printf("%s: %zu units complete on Slurm, %llu views validated: ok\n",
                layout.db_dir.string().c_str(),
                after->size(),
                static_cast<unsigned long long>(report.views));
  }
  return kExitOk;
}

// ---- handdb unit
// ---------------------------------------------------------------------------------

int RunUnit(int argc, char** argv) {
  CLI::App app(
      "Per-unit work, as run by the Slurm array tasks of `handdb generate --slurm` (one task = one "
      "render unit) and `handdb evaluate --slurm` (one task = one slice of the test views). Every "
      "subcommand is idempotent: finished renders, complete shards and parts are kept.",
      "handdb unit");
  app.require_subcommand(1);
  bool quiet = false;

  fs::path plan_path, run_dir, db_dir, blender;
  int64_t unit = -1;
  int threads = 0;
  ConvertFlags convert_flags;
  bool as_json = false;

  auto* render = app.add_subcommand("render", "render one unit of a plan with Blender");
  render->add_option("PLAN", plan_path, "plan.json")->required();
  render->add_option("--unit", unit, "unit id")->required()->check(CLI::NonNegativeNumber);
  render->add_option("--out,-o", run_dir, "render directory (RUN_DIR)")->required();
  render->add_option("--blender", blender, "Blender executable (default: $HANDDB_BLENDER or PATH)");
  render->add_flag("--quiet,-q", quiet, "no progress display");

  auto* convert = app.add_subcommand("convert", "convert one rendered unit into its shard");
  convert->add_option("RUN_DIR", run_dir, "render directory (plan.json, units/)")->required();
  convert->add_option("--unit", unit, "unit id")->required()->check(CLI::NonNegativeNumber);
  convert->add_option("--out,-o", db_dir, "database directory")->required();
  convert->add_option("--threads,-j", threads, "threads (default: $SLURM_CPUS_PER_TASK or 1)")
      ->check(CLI::PositiveNumber);
  convert_flags.Add(*convert);
  convert->add_flag("--quiet,-q", quiet, "no progress display");

  auto* finalize = app.add_subcommand(
      "finalize", "write the manifest once every shard is complete, then validate the database");
  finalize->add_option("RUN_DIR", run_dir, "render directory (plan.json, units/)")->required();
  finalize->add_option("--out,-o", db_dir, "database directory")->required();
  finalize->add_option("--threads,-j", threads, "threads (default: $SLURM_CPUS_PER_TASK or 1)")
      ->check(CLI::PositiveNumber);
  convert_flags.Add(*finalize);
  finalize->add_flag("--quiet,-q", quiet, "no progress display");
  finalize->add_flag("--json", as_json, "print the summary as JSON on stdout");

  auto* status = app.add_subcommand(
      "status", "which units have a complete shard; why the others failed on Slurm");
  status->add_option("RUN_DIR", run_dir, "render directory (plan.json, units/)")->required();
  status->add_option("--out,-o", db_dir, "database directory")->required();
  convert_flags.Add(*status);
  status->add_flag("--json", as_json, "print the status as JSON on stdout");

  // unit evaluate | evaluate-merge: the tasks of `handdb evaluate --slurm`.
  UnitEvaluateCommands evaluate_commands(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kExitOk : kExitUsage;
  }
  if (evaluate_commands.parsed()) return evaluate_commands.Run();
  if (threads <= 0) threads = TaskThreads();

  if (render->parsed()) {
    const std::string cmd = "unit render";
    RenderOptions options;
    options.jobs = 1;
    options.blender = blender;
    options.units = {static_cast<uint32_t>(unit)};
    options.progress = !quiet;
    auto plan = ReadPlan(plan_path);
    if (!plan.ok()) return Fail(cmd, plan.status());
    if (static_cast<uint64_t>(unit) >= plan->units.size()) {
      return Fail(cmd,
                  Status(StatusCode::kOutOfRange,
                         plan_path.string() + ": no unit " + std::to_string(unit) +
                             " (the plan has " + std::to_string(plan->units.size()) + ")"));
    }
    auto summary = RenderPlan(plan_path, run_dir, options);
    if (!summary.ok()) return Fail(cmd, summary.status());
    std::printf("unit %lld: %llu renders (%s) in %.1f s\n",
                static_cast<long long>(unit),
                static_cast<unsigned long long>(summary->renders_done),
                summary->units_skipped > 0 ? "already done" : "rendered",
                summary->seconds);
    return kExitOk;
  }

  if (convert->parsed()) {
    const std::string cmd = "unit convert";
    ConvertOptions options = convert_flags.Get(threads, !quiet);
    options.units = {static_cast<uint32_t>(unit)};
    std::vector<SkippedView> bad;
    auto summary = ConvertRenderDir(run_dir, db_dir, options, &bad);
    if (!summary.ok()) {
      for (const auto& b : bad) {
        std::fprintf(stderr,
                     "handdb %s: %s: %s\n",
                     cmd.c_str(),
                     (run_dir / b.file).c_str(),
                     b.reason.c_str());
      }
      return Fail(cmd, summary.status());
    }
    std::printf("unit %lld: shard %s (%llu views, %llu bytes, %zu skipped) in %.1f s\n",
                static_cast<long long>(unit),
                summary->shards_kept > 0 ? "kept" : "written",
                static_cast<unsigned long long>(summary->views),
                static_cast<unsigned long long>(summary->bytes),
                summary->skipped.size(),
                summary->seconds);
    return kExitOk;
  }

  if (finalize->parsed()) {
    const std::string cmd = "unit finalize";
    const ConvertOptions options = convert_flags.Get(threads, !quiet);
    auto complete = FindCompleteShards(run_dir, db_dir, options);
    if (!complete.ok()) return Fail(cmd, complete.status());
    std::vector<uint32_t> missing;
    for (uint32_t u = 0; u < complete->size(); ++u) {
      if (!(*complete)[u]) missing.push_back(u);
    }
    if (!missing.empty()) {
      return Fail(cmd,
                  Status(StatusCode::kNotFound,
                         db_dir.string() + ": " + std::to_string(missing.size()) +
                             " units have no complete shard yet (" + FormatArrayRanges(missing) +
                             "); run their tasks first"));
    }
    auto summary = ConvertRenderDir(run_dir, db_dir, options);
    if (!summary.ok()) return Fail(cmd, summary.status());
    ValidateOptions vopt;
    vopt.show_progress = !quiet;
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
    if (as_json) {
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

  // status
  const std::string cmd = "unit status";
  auto complete = FindCompleteShards(run_dir, db_dir, convert_flags.Get(1, false));
  if (!complete.ok()) return Fail(cmd, complete.status());
  const auto pending = PendingUnits(static_cast<uint32_t>(complete->size()),
                                    [&](uint32_t u) { return (*complete)[u]; });
  SlurmGenerateLayout layout;
  layout.run_dir = run_dir;
  layout.db_dir = db_dir;
  layout.slurm_dir = run_dir / "slurm";
  std::vector<UnitFailure> failures;
  std::error_code ec;
  if (fs::exists(layout.jobs_file(), ec)) {
    auto sub = ReadSubmissionRecord(layout.jobs_file());
    if (!sub.ok()) return Fail(cmd, sub.status());
    auto abs_db = Absolute(db_dir);
    if (abs_db.ok() && sub->db_dir == abs_db->string()) {
      // Without Slurm commands (e.g. on a login node without them) the markers still tell.
      auto jobs = QueryJobs(JobIds(*sub));
      failures = CollectFailures(
          layout, *sub, *complete, jobs.ok() ? *jobs : std::vector<SlurmJobState>{});
    }
  }
  if (as_json) {
    json f = json::array();
    for (const auto& x : failures) {
      f.push_back({{"unit", x.unit}, {"reason", x.reason}, {"log", x.log.string()}});
    }
    std::printf("%s\n",
                json({{"units", complete->size()},
                      {"complete", complete->size() - pending.size()},
                      {"pending", pending},
                      {"failed", f}})
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

}  // namespace handdb::cli
