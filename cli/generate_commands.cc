// `handdb plan` and `handdb render` (docs/generator.md): a generation config becomes a render plan,
// and the plan's units are rendered by parallel Blender workers.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli/cli_util.h"
#include "cli/commands.h"
#include "generator/plan/plan.h"
#include "generator/render/render_driver.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

}  // namespace

int RunPlan(int argc, char** argv) {
  CLI::App app(
      "Turn a generation config (schemas/config.schema.json) into a render plan: sampled hand "
      "shapes x view directions, cut into units of at most unit_size renders. The same config "
      "gives the same bytes.",
      "handdb plan");
  std::string config;
  std::string out;
  bool as_json = false;
  app.add_option("config", config, "generation config JSON (e.g. configs/demo.json)")->required();
  app.add_option("-o,--output", out, "plan file to write")->required();
  app.add_flag("--json", as_json, "print the summary as JSON on stdout");
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;

  PlanSummary s;
  Status status = WritePlanFromConfig(config, out, &s);
  if (!status.ok()) return Fail("plan", status);
  if (as_json) {
    json j = {{"plan", out},
              {"shapes", s.shapes},
              {"shapes_method", s.shapes_method},
              {"clamped_shapes", s.clamped_shapes},
              {"directions", s.directions},
              {"views_method", s.views_method},
              {"covering_radius_deg", s.covering_radius_deg},
              {"rolls", s.rolls},
              {"renders", s.renders},
              {"views", s.views},
              {"units", s.units}};
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf(
        "%s: %llu shapes (%s, %llu clamped) x %llu directions (%s, covering radius %.2f deg) = "
        "%llu renders in %llu units; x %llu rolls = %llu views\n",
        out.c_str(),
        static_cast<unsigned long long>(s.shapes),
        s.shapes_method.c_str(),
        static_cast<unsigned long long>(s.clamped_shapes),
        static_cast<unsigned long long>(s.directions),
        s.views_method.c_str(),
        s.covering_radius_deg,
        static_cast<unsigned long long>(s.renders),
        static_cast<unsigned long long>(s.units),
        static_cast<unsigned long long>(s.rolls),
        static_cast<unsigned long long>(s.views));
  }
  return kExitOk;
}

int RunRender(int argc, char** argv) {
  CLI::App app(
      "Render a plan's units with parallel headless Blender workers into OUT/units/uNNNNN/ "
      "(label+depth EXRs and pose sidecars). Resumable: finished units (DONE marker) and views are "
      "skipped. Worker logs: OUT/logs/uNNNNN.log. Ctrl-C stops the workers and keeps finished "
      "views.",
      "handdb render");
  std::string plan;
  std::string out;
  RenderOptions options;
  std::string blender;
  bool quiet = false;
  bool as_json = false;
  app.add_option("plan", plan, "plan JSON written by `handdb plan`")->required();
  app.add_option("--out", out, "run directory")->required();
  app.add_option("-j,--jobs", options.jobs, "parallel Blender processes")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
  app.add_option("--blender", blender, "Blender executable (default: $HANDDB_BLENDER, else PATH)");
  app.add_option("--units", options.units, "render only these unit ids");
  app.add_option("--retries", options.max_retries, "extra attempts for a failed unit")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  app.add_option("--frames-per-process",
                 options.frames_per_process,
                 "restart Blender every N renders within a unit (0: script default)")
      ->check(CLI::Range(0, 1000000));
  app.add_option("--stall-timeout",
                 options.stall_timeout_seconds,
                 "kill a Blender worker (and retry its unit) when no render of its unit finished "
                 "for this many seconds (0: never)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_flag("-q,--quiet", quiet, "no progress bar");
  app.add_flag("--json", as_json, "print the summary as JSON on stdout");
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  options.blender = blender;
  options.progress = !quiet;

  Result<RenderSummary> r = RenderPlan(plan, out, options);
  if (!r.ok()) return Fail("render", r.status());
  const RenderSummary& s = *r;
  const double rate =
      s.seconds > 0 && s.units_rendered > 0 ? static_cast<double>(s.renders_done) / s.seconds : 0.0;
  if (as_json) {
    json j = {{"out", out},
              {"units", s.units_total},
              {"units_skipped", s.units_skipped},
              {"units_rendered", s.units_rendered},
              {"retries", s.retries},
              {"renders", s.renders_total},
              {"renders_done", s.renders_done},
              {"seconds", std::round(s.seconds * 1000) / 1000}};
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!quiet) {
    char rate_text[48] = "";
    if (rate > 0) std::snprintf(rate_text, sizeof(rate_text), " (%.1f renders/s)", rate);
    std::fprintf(
        stderr,
        "render: %u units (%u rendered, %u already done, %u retries), %llu/%llu renders in "
        "%.1f s%s\n",
        s.units_total,
        s.units_rendered,
        s.units_skipped,
        s.retries,
        static_cast<unsigned long long>(s.renders_done),
        static_cast<unsigned long long>(s.renders_total),
        s.seconds,
        rate_text);
  }
  return kExitOk;
}

}  // namespace handdb::cli
