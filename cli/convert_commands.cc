// `handdb convert`, `handdb generate` and `handdb show` (docs/conversion.md).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "base/atomic_file.h"
#include "base/directory_lock.h"
#include "base/image_encode.h"
#include "base/json_schema.h"
#include "base/thread_pool.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/slurm_cli.h"
#include "cli/slurm_commands.h"
#include "format/manifest.h"
#include "format/roll.h"
#include "format/validator.h"
#include "format/view.h"
#include "generator/convert/converter.h"
#include "generator/pipeline.h"
#include "generator/plan/plan.h"
#include "generator/render/render_driver.h"
#include "query/database.h"
#include "query/index/database_index.h"
#include "query/index/view_index.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr const char* kDepthJumpHelp =
    "depth difference (scene units, metres) that makes a joint-pair border an occlusion edge";

json SummaryJson(const ConvertSummary& s, const fs::path& db_dir) {
  json skipped = json::array();
  for (const auto& v : s.skipped) {
    skipped.push_back({{"render_id", v.render_id}, {"file", v.file}, {"reason", v.reason}});
  }
  return {{"db", db_dir.string()},
          {"units", s.units_total},
          {"shards_written", s.shards_written},
          {"shards_kept", s.shards_kept},
          {"views", s.views},
          {"virtual_views", s.views * s.rolls},
          {"points", s.points},
          {"bytes", s.bytes},
          {"skipped", skipped},
          {"seconds", s.seconds}};
}

void PrintSummary(const char* cmd, const ConvertSummary& s, const fs::path& db_dir) {
  std::printf(
      "%s: %llu canonical views (%llu virtual) in %u shards (%u written, %u kept), %llu points, "
      "%.1f MB, %zu skipped, %.1f s\n",
      db_dir.string().c_str(),
      static_cast<unsigned long long>(s.views),
      static_cast<unsigned long long>(s.views * s.rolls),
      s.units_total,
      s.shards_written,
      s.shards_kept,
      static_cast<unsigned long long>(s.points),
      static_cast<double>(s.bytes) / 1e6,
      s.skipped.size(),
      s.seconds);
  (void)cmd;
}

// Prints the bad views (one line each, at most `limit`) of a failed conversion.
void PrintBad(const char* cmd, const fs::path& render_dir, const std::vector<SkippedView>& bad) {
  constexpr size_t kLimit = 20;
  for (size_t i = 0; i < bad.size() && i < kLimit; ++i) {
    std::fprintf(stderr,
                 "handdb %s: %s: %s\n",
                 cmd,
                 (render_dir / bad[i].file).string().c_str(),
                 bad[i].reason.c_str());
  }
  if (bad.size() > kLimit) {
    std::fprintf(stderr, "handdb %s: ... and %zu more bad views\n", cmd, bad.size() - kLimit);
  }
}

}  // namespace

constexpr const char* kCodedHelp =
    "write coded shards (format v1.2, ~4x smaller; points and fields decoded when read: for "
    "databases searched through an index; docs/format.md section 10)";

int RunConvert(int argc, char** argv) {
  CLI::App app(
      "Convert a render directory (plan.json + units/) into a database: one shard per "
      "render unit plus manifest.json. Bad inputs stop the run before anything is "
      "written, unless --skip-bad. Rerunning keeps shards that are already complete.",
      "handdb convert");
  fs::path render_dir, db_dir;
  ConvertOptions options;
  EdgeFlags edges;
  bool quiet = false, as_json = false;
  app.add_option("RENDER_DIR", render_dir, "render directory (plan.json, units/)")->required();
  app.add_option("--out,-o", db_dir, "database directory to write")->required();
  app.add_option("--threads,-j", options.num_threads, "worker threads (default: all cores)")
      ->check(CLI::PositiveNumber);
  app.add_flag("--skip-bad",
               options.skip_bad,
               "leave bad views out (recorded in the manifest's 'skipped') instead of failing");
  app.add_flag("--coded", options.coded, kCodedHelp);
  edges.Add(app, kDepthJumpHelp);
  app.add_flag("--quiet,-q", quiet, "no progress display");
  app.add_flag("--json", as_json, "print the summary as JSON on stdout");
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  options.edges = edges.Get();
  options.progress = !quiet;
  // One writer per database directory (base/directory_lock.h).
  std::error_code ec;
  fs::create_directories(db_dir, ec);
  if (ec) {
    return Fail("convert",
                Status(StatusCode::kIoError, db_dir.string() + ": cannot create: " + ec.message()));
  }
  auto lock = DirectoryLock::Acquire(db_dir);
  if (!lock.ok()) return Fail("convert", lock.status());
  std::vector<SkippedView> bad;
  auto summary = ConvertRenderDir(render_dir, db_dir, options, &bad);
  if (!summary.ok()) {
    if (!bad.empty() && !options.skip_bad) PrintBad("convert", render_dir, bad);
    return Fail("convert", summary.status());
  }
  if (as_json) {
    std::printf("%s\n", SummaryJson(*summary, db_dir).dump(2).c_str());
  } else {
    PrintSummary("convert", *summary, db_dir);
  }
  return kExitOk;
}

int RunGenerate(int argc, char** argv) {
  CLI::App app(
      "Build a database from a generation config: plan -> render (Blender) -> convert -> "
      "validate. Resumable: rerun the same command after an interruption.",
      "handdb generate");
  fs::path config_path, db_dir, work_dir, blender;
  int jobs = 0;
  ConvertOptions convert;
  EdgeFlags edges;
  bool quiet = false, as_json = false;
  app.add_option("CONFIG", config_path, "generation config (schemas/config.schema.json)")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--out,-o", db_dir, "database directory to write")->required();
  app.add_option("--work", work_dir, "render directory (default: DB_DIR/render)");
  app.add_option("--jobs,-j",
                 jobs,
                 "parallel Blender processes and convert threads (default: "
                 "all cores)")
      ->check(CLI::PositiveNumber);
  app.add_option("--blender", blender, "Blender executable (default: $HANDDB_BLENDER or PATH)");
  RenderOptions render;
  app.add_option("--stall-timeout",
                 render.stall_timeout_seconds,
                 "kill a Blender worker (and retry its unit) when no render of its unit finished "
                 "for this many seconds (0: never)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_flag("--skip-bad", convert.skip_bad, "leave bad views out instead of failing");
  app.add_flag("--coded", convert.coded, kCodedHelp);
  edges.Add(app, kDepthJumpHelp);
  bool build_index = false;
  app.add_flag("--index",
               build_index,
               "then build the search index (handdb index DB with its defaults; on Slurm, in the "
               "final job)");
  app.add_flag("--quiet,-q", quiet, "no progress display");
  app.add_flag("--json", as_json, "print the summary as JSON on stdout");
  SlurmFlags slurm;  // --slurm and its options (cli/slurm_cli.h)
  slurm.Add(app);
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  jobs = ResolveNumThreads(jobs);

  GenerateOptions options;
  options.config_path = config_path;
  options.db_dir = db_dir;
  options.work_dir = work_dir;
  options.render = render;
  options.render.jobs = jobs;
  options.render.blender = blender;
  options.convert = convert;
  options.convert.num_threads = jobs;
  options.convert.edges = edges.Get();
  options.progress = !quiet;
  if (build_index) {
    // As `handdb index DB` would; this run already holds DB's lock.
    options.index_step = [jobs, quiet, as_json](const fs::path& db) -> Status {
      IndexBuildOptions index_options;
      index_options.num_threads = jobs;
      index_options.progress = !quiet;
      auto written = WriteDatabaseIndex(db, index_options);
      if (!written.ok()) return written.status();
      if (!as_json) PrintIndexSummary("handdb generate", db, *written);
      return Status::Ok();
    };
  }
  options.on_stage = [quiet](int k, int stages, const char* what) {
    if (!quiet) std::fprintf(stderr, "handdb generate: [%d/%d] %s\n", k, stages, what);
  };
  if (std::string error; !options.Check(&error)) {
    std::fprintf(stderr, "handdb generate: %s\n", error.c_str());
    return kExitUsage;
  }
  GeneratePipeline pipeline(std::move(options));
  if (Status s = pipeline.Plan(); !s.ok()) return Fail("generate", s);

  // On Slurm: one array task per unit (render + convert), then a final job (manifest, validate).
  if (slurm.enabled) {
    convert.edges = edges.Get();
    // The tasks convert with the edge flags as typed here, so they convert as this run would.
    std::vector<std::string> convert_args = edges.Typed();
    if (convert.skip_bad) convert_args.push_back("--skip-bad");
    if (convert.coded) convert_args.push_back("--coded");
    return RunGenerateOnSlurm(
        {db_dir, pipeline.work_dir(), blender, convert, convert_args, build_index, quiet, as_json},
        slurm);
  }

  GenerateSummary result;
  if (Status s = pipeline.Run(&result); !s.ok()) {
    if (!result.bad.empty() && !convert.skip_bad) {
      PrintBad("generate", pipeline.work_dir(), result.bad);
    }
    for (const auto& p : result.validation.problems) {
      std::fprintf(stderr, "handdb generate: %s\n", p.message.c_str());
    }
    return Fail("generate", s);
  }
  const ConvertSummary* summary = &result.convert;
  const RenderSummary* rendered = &result.render;
  const ValidationReport& report = result.validation;
  if (as_json) {
    json out = SummaryJson(*summary, db_dir);
    out["render"] = {{"units", rendered->units_total},
                     {"units_rendered", rendered->units_rendered},
                     {"units_skipped", rendered->units_skipped},
                     {"renders", rendered->renders_total},
                     {"seconds", rendered->seconds}};
    out["validated_views"] = report.views;
    if (build_index) {
      auto manifest = ReadManifest(db_dir);
      if (manifest.ok() && manifest->index) {
        out["index"] = {{"file", manifest->index->file}, {"bytes", manifest->index->bytes}};
      }
    }
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("rendered %u units (%u already done) in %.1f s\n",
                rendered->units_total,
                rendered->units_skipped,
                rendered->seconds);
    PrintSummary("generate", *summary, db_dir);
    std::printf("validated %llu views: ok\n", static_cast<unsigned long long>(report.views));
  }
  return kExitOk;
}

namespace {

// Finger chains of the 21 keypoints (docs/conventions.md): wrist, then 4 per finger.
void DrawSkeleton(cv::Mat& img, const ViewLabel& label, const cv::Point2d& origin, double scale) {
  const cv::Scalar colours[5] = {
      {60, 60, 255}, {60, 200, 60}, {255, 160, 40}, {40, 220, 240}, {220, 80, 220}};
  auto at = [&](int k) {
    return cv::Point(static_cast<int>(std::lround(origin.x + scale * label.keypoints[k][0])),
                     static_cast<int>(std::lround(origin.y + scale * label.keypoints[k][1])));
  };
  for (int f = 0; f < 5; ++f) {
    int prev = 0;
    for (int j = 0; j < 4; ++j) {
      const int k = 1 + 4 * f + j;
      cv::line(img, at(prev), at(k), colours[f], 1, cv::LINE_AA);
      prev = k;
    }
  }
  for (int k = 0; k < kNumKeypoints; ++k) {
    const cv::Scalar c = k == 0 ? cv::Scalar(255, 255, 255) : colours[(k - 1) / 4];
    cv::circle(img, at(k), 3, c, cv::FILLED, cv::LINE_AA);
  }
}

// CRC-32 (ISO 3309, as PNG chunks use it) of `data`.
uint32_t Crc32(std::string_view data) {
  uint32_t crc = 0xFFFFFFFFu;
  for (const char c : data) {
    crc ^= static_cast<uint8_t>(c);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return crc ^ 0xFFFFFFFFu;
}

// Inserts a tEXt chunk (keyword, Latin-1 text) right after the IHDR chunk of an encoded PNG, so
// the caption travels with the file without touching a pixel.
void AddPngText(std::vector<uint8_t>* png, const std::string& keyword, const std::string& text) {
  constexpr size_t kAfterIhdr = 8 + 4 + 4 + 13 + 4;  // signature, length, type, data, CRC
  if (png->size() < kAfterIhdr) return;
  const std::string body = "tEXt" + keyword + '\0' + text;
  std::string chunk;
  const auto be32 = [&chunk](uint32_t v) {
    for (int shift = 24; shift >= 0; shift -= 8) chunk.push_back(static_cast<char>(v >> shift));
  };
  be32(static_cast<uint32_t>(body.size() - 4));
  chunk += body;
  be32(Crc32(body));
  png->insert(png->begin() + kAfterIhdr, chunk.begin(), chunk.end());
}

}  // namespace

int RunShow(int argc, char** argv) {
  CLI::App app("Draw a stored view's edge points (optionally rolled, with keypoints) as a PNG.",
               "handdb show");
  fs::path db_dir, out_path;
  int64_t view = -1;
  int64_t roll = 0;
  int size = 384;
  bool keypoints = false;
  app.add_option("DB", db_dir, "database directory")->required();
  app.add_option("--view", view, "canonical view index (manifest order)")->required();
  app.add_option("--roll", roll, "roll index 0..R-1")->capture_default_str();
  bool draw_caption = false;
  app.add_flag("--keypoints", keypoints, "draw the 21 keypoints and the finger chains");
  app.add_flag("--caption",
               draw_caption,
               "draw the caption (view, roll, shape, points) into the image; without it the "
               "caption is only the PNG's Description text, so the image is a clean edge image "
               "`handdb query` reads back");
  app.add_option("--size", size, "image size in px (the normalised frame is 192 px across)")
      ->check(CLI::Range(64, 4096))
      ->capture_default_str();
  app.add_option("-o,--out", out_path, "output PNG")->required();
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;

  auto db = Database::Open(db_dir);
  if (!db.ok()) return Fail("show", db.status());
  if (view < 0 || static_cast<uint64_t>(view) >= db->num_views()) {
    return Fail(
        "show",
        Status(StatusCode::kOutOfRange,
               db_dir.string() + ": view " + std::to_string(view) + " out of range (database has " +
                   std::to_string(db->num_views()) + " canonical views)"));
  }
  if (roll < 0 || roll >= static_cast<int64_t>(db->num_rolls())) {
    return Fail("show",
                Status(StatusCode::kOutOfRange,
                       "roll " + std::to_string(roll) + " out of range 0.." +
                           std::to_string(db->num_rolls() - 1)));
  }
  const auto v = static_cast<view_id_t>(view);
  const float angle = RollAngle(static_cast<roll_id_t>(roll), db->num_rolls());
  std::span<const PointQ> points;
  try {
    points = db->points(v);
  } catch (const CodedViewError& e) {
    // A coded view damaged past what Open checks: its shard and view, like validate says it.
    return Fail("show", e.status());
  }
  std::vector<Point2f> pts;
  RollPoints(points, angle, &pts);
  const ViewLabel label = RollLabel(db->label(v), angle);

  // The normalised frame's points lie within 192 * sqrt(3) / 2 = 166 px of the origin.
  const double scale = size / 384.0;
  const cv::Point2d origin(size / 2.0, size / 2.0);
  cv::Mat img(size, size, CV_8UC3, cv::Scalar(0, 0, 0));
  for (const Point2f& p : pts) {
    const int x = static_cast<int>(std::floor(origin.x + scale * p.x));
    const int y = static_cast<int>(std::floor(origin.y + scale * p.y));
    if (x >= 0 && y >= 0 && x < size && y < size) img.at<cv::Vec3b>(y, x) = {235, 235, 235};
  }
  if (keypoints) DrawSkeleton(img, label, origin, scale);
  const std::string shape(db->shape_name(label.shape_id));
  const std::string caption = "view " + std::to_string(view) + " roll " + std::to_string(roll) +
                              "/" + std::to_string(db->num_rolls()) +
                              (shape.empty() ? "" : "  " + shape) + "  " +
                              std::to_string(points.size()) + " pts";
  // An anti-aliased caption in the pixels would make `query` take the image for a photo (and
  // with --input edges the caption would become edges), so the tool's own output would not
  // find its own view. By default the pixels are the edges only (one grey level on black, what
  // query's auto-detection calls an edge image) and the caption is PNG text.
  if (draw_caption) {
    cv::putText(img,
                caption,
                cv::Point(6, 16),
                cv::FONT_HERSHEY_SIMPLEX,
                0.4,
                cv::Scalar(160, 160, 160),
                1,
                cv::LINE_AA);
  }
  auto encoded = EncodePng({img.data, img.cols, img.rows, img.channels(), img.step[0]});
  if (!encoded.ok()) {
    return Fail("show",
                Status(StatusCode::kIoError,
                       out_path.string() + ": PNG encoding failed: " + encoded.status().message()));
  }
  std::vector<uint8_t>& png = *encoded;
  AddPngText(&png, "Description", "handdb show " + db_dir.string() + ": " + caption);
  Status s = WriteFileAtomic(
      out_path, std::string_view(reinterpret_cast<const char*>(png.data()), png.size()));
  if (!s.ok()) return Fail("show", s);
  return kExitOk;
}

}  // namespace handdb::cli
