// Convert throughput (docs/conversion.md): views/s of ConvertRenderDir with 1 and 2 threads
// (1 thread is the baseline of the same run), the per-view split (EXR read, sidecar, edges +
// normalisation), edge points per view and bytes per canonical and per virtual view.
//
//   convert_bench --render-dir RUN_DIR   real renders (e.g. from `handdb generate
//   configs/demo.json`) convert_bench [--shapes 26 --dirs 40] synthetic hands written in the render
//   layout, once as
//                                        Blender writes them now (Combined RGBA + Depth + IndexMA,
//                                        float32, ZIP) and once as 2 half-float channels
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "edges/exr_io.h"
#include "edges/synthetic_hand.h"
#include "format/manifest.h"
#include "generator/convert/converter.h"
#include "generator/plan/plan.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// User + system CPU seconds of this process so far: with 2 cores shared by other work, views
// per CPU-second is the number that does not depend on the load.
double CpuSeconds() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_utime.tv_sec + ru.ru_stime.tv_sec +
         1e-6 * (ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

[[noreturn]] void Die(const Status& s) {
  std::fprintf(stderr, "convert_bench: %s\n", s.ToString().c_str());
  std::exit(1);
}

// A synthetic render dir: plan from a small config, synthetic hands as label EXRs + sidecars.
void MakeSyntheticRenderDir(const fs::path& run, int shapes, int dirs, const ExrWriteOptions& exr) {
  fs::remove_all(run);
  fs::create_directories(run);
  const json config = {{"seed", 1},
                       {"shapes", {{"method", "basic"}, {"count", shapes}}},
                       {"views", {{"method", "fibonacci"}, {"count", dirs}}},
                       {"rolls", 48},
                       {"unit_size", 256},
                       {"render", {{"resolution", 256}}}};
  if (Status s = WriteFileAtomic(run / "config.json", config.dump()); !s.ok()) Die(s);
  if (Status s = WritePlanFromConfig(run / "config.json", run / "plan.json"); !s.ok()) Die(s);
  auto plan = ReadPlan(run / "plan.json");
  if (!plan.ok()) Die(plan.status());
  for (const PlanUnit& unit : plan->units) {
    const fs::path dir = run / "units" / UnitDirName(unit.id);
    fs::create_directories(dir);
    for (const PlanRender& r : unit.renders) {
      SyntheticHandParams p;
      p.angle = 0.37 * r.dir_id + 0.9 * r.shape_id;
      for (int f = 0; f < 5; ++f) {
        p.bend[f] = 0.3 * std::sin(1.7 * r.shape_id + f);
        p.folded[f] = ((r.shape_id >> f) & 1) != 0 && f > 0;
      }
      p.scale = 0.8 + 0.3 * std::cos(0.5 * r.dir_id);
      const SyntheticHand hand = RenderSyntheticHand(p);
      if (Status s = WriteLabelExr(dir / (RenderFileStem(r.render_id) + ".exr"), hand.image, exr);
          !s.ok()) {
        Die(s);
      }
      const PlanDirection& d = plan->directions[r.dir_id];
      json kp_px = json::array(), kp_cam = json::array();
      for (const auto& k : hand.keypoints_px) {
        kp_px.push_back({k[0], k[1], k[2]});
        kp_cam.push_back({0.0, 0.0, 0.0});
      }
      const json sidecar = {{"render_id", r.render_id},
                            {"unit", unit.id},
                            {"shape_id", r.shape_id},
                            {"shape_name", plan->shapes[r.shape_id].name},
                            {"dir_id", r.dir_id},
                            {"joint_angles", plan->shapes[r.shape_id].joints},
                            {"view_direction", d.direction},
                            {"view_theta", d.theta},
                            {"view_phi", d.phi},
                            {"camera_roll", 0.0},
                            {"resolution", 256},
                            {"ortho_scale", plan->ortho_scale},
                            {"keypoints_cam", kp_cam},
                            {"keypoints_px", kp_px},
                            {"blender_version", "synthetic"},
                            {"script_version", "bench"},
                            {"hand_model_sha256", plan->hand_model_sha256}};
      if (Status s = WriteJsonFileAtomic(dir / (RenderFileStem(r.render_id) + ".json"), sidecar);
          !s.ok()) {
        Die(s);
      }
    }
    if (Status s = WriteFileAtomic(dir / "DONE", ""); !s.ok()) Die(s);
  }
}

void Measure(const std::string& name, const fs::path& run, const fs::path& scratch) {
  auto plan = ReadPlan(run / "plan.json");
  if (!plan.ok()) Die(plan.status());
  uint64_t exr_bytes = 0;
  size_t n = 0;
  for (const PlanUnit& unit : plan->units) {
    for (const PlanRender& r : unit.renders) {
      exr_bytes += fs::file_size(run / "units" / UnitDirName(unit.id) /
                                 (RenderFileStem(r.render_id) + ".exr"));
      ++n;
    }
  }
  std::printf("\n== %s: %s, %zu renders, %d px, EXR %.1f KB/render\n",
              name.c_str(),
              run.string().c_str(),
              n,
              plan->resolution,
              exr_bytes / 1024.0 / n);

  // Per-view split, one thread, files hot in the page cache (the runs below read them again).
  ExrReadOptions ropt;
  ropt.expected_width = ropt.expected_height = plan->resolution;
  ViewConversionOptions vopt;
  double t_exr = 0, t_side = 0, t_conv = 0;
  std::vector<size_t> points;
  for (const PlanUnit& unit : plan->units) {
    for (const PlanRender& r : unit.renders) {
      const fs::path stem = run / "units" / UnitDirName(unit.id) / RenderFileStem(r.render_id);
      const auto t0 = Clock::now();
      auto image = ReadLabelExr(stem.string() + ".exr", ropt);
      const auto t1 = Clock::now();
      auto side = ReadSidecar(stem.string() + ".json");
      const auto t2 = Clock::now();
      if (!image.ok()) Die(image.status());
      if (!side.ok()) Die(side.status());
      auto view = ConvertView(*image, *side, vopt, stem.string());
      const auto t3 = Clock::now();
      if (!view.ok()) Die(view.status());
      t_exr += Seconds(t0, t1);
      t_side += Seconds(t1, t2);
      t_conv += Seconds(t2, t3);
      points.push_back(view->points.size());
    }
  }
  std::sort(points.begin(), points.end());
  double mean = 0;
  for (size_t p : points) mean += static_cast<double>(p) / points.size();
  std::printf("per view (1 thread): EXR read %.2f ms, sidecar %.2f ms, edges+normalise %.2f ms\n",
              1e3 * t_exr / n,
              1e3 * t_side / n,
              1e3 * t_conv / n);
  std::printf("edge points per view: mean %.0f, median %zu, p95 %zu, max %zu\n",
              mean,
              points[points.size() / 2],
              points[points.size() * 95 / 100],
              points.back());

  // Whole runs: 1 thread (baseline) and 2 threads, fresh output each time.
  double views_per_s[3] = {0, 0, 0};
  ConvertSummary last;
  for (int threads : {1, 2}) {
    const fs::path db = scratch / ("db-" + std::to_string(threads));
    fs::remove_all(db);
    ConvertOptions copt;
    copt.num_threads = threads;
    copt.progress = false;
    const auto t0 = Clock::now();
    const double cpu0 = CpuSeconds();
    auto s = ConvertRenderDir(run, db, copt);
    const double sec = Seconds(t0, Clock::now());
    const double cpu = CpuSeconds() - cpu0;
    if (!s.ok()) Die(s.status());
    views_per_s[threads] = static_cast<double>(s->views) / sec;
    std::printf(
        "convert, %d thread%s: %.2f s, %.0f canonical views/s (%.0f virtual views/s); %.2f CPU s "
        "= %.0f views per CPU-second\n",
        threads,
        threads > 1 ? "s" : " ",
        sec,
        views_per_s[threads],
        views_per_s[threads] * s->rolls,
        cpu,
        s->views / cpu);
    last = *s;
    fs::remove_all(db);
  }
  double load[3] = {0, 0, 0};
  getloadavg(load, 3);
  std::printf(
      "2 threads vs 1 thread: x%.2f   target >= 500 canonical views/s with 2 threads: %s (load "
      "average %.1f on %u cores while measuring)\n",
      views_per_s[2] / views_per_s[1],
      views_per_s[2] >= 500 ? "met" : "NOT met",
      load[0],
      std::thread::hardware_concurrency());
  std::printf(
      "shard bytes: %.0f per canonical view, %.1f per virtual view (R = %u); %.1f bytes per "
      "point\n",
      static_cast<double>(last.bytes) / last.views,
      static_cast<double>(last.bytes) / last.views / last.rolls,
      last.rolls,
      static_cast<double>(last.bytes) / last.points);
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  using namespace handdb;
  std::string render_dir;
  int shapes = 26, dirs = 40;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "convert_bench: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--render-dir") {
      render_dir = next();
    } else if (a == "--shapes") {
      shapes = std::atoi(next().c_str());
    } else if (a == "--dirs") {
      dirs = std::atoi(next().c_str());
    } else {
      std::fprintf(stderr, "usage: convert_bench [--render-dir RUN_DIR] [--shapes N --dirs M]\n");
      return a == "--help" ? 0 : 2;
    }
  }
  const fs::path scratch =
      fs::temp_directory_path() / ("handdb_convert_bench_" + std::to_string(::getpid()));
  fs::create_directories(scratch);
  if (!render_dir.empty()) {
    Measure("real renders", render_dir, scratch);
  } else {
    std::printf(
        "synthetic hands (edges/synthetic_hand.h), %d shapes x %d directions\n", shapes, dirs);
    ExrWriteOptions blender_like;
    blender_like.combined_pass = true;
    MakeSyntheticRenderDir(scratch / "run-blender-layout", shapes, dirs, blender_like);
    Measure("synthetic, Blender's layout (Combined RGBA + Depth + IndexMA, float32, ZIP)",
            scratch / "run-blender-layout",
            scratch);
    ExrWriteOptions half;
    half.half = true;
    MakeSyntheticRenderDir(scratch / "run-half", shapes, dirs, half);
    Measure("synthetic, Depth + IndexMA only, half float, ZIP", scratch / "run-half", scratch);
  }
  fs::remove_all(scratch);
  return 0;
}
