// `handdb testset` and `handdb evaluate` (docs/evaluation.md): render held-out test views
// with ground truth, and score a database's retrieval on them (the paper's Table 1,
// success@(d, n), keypoint error, queries per second).
#include <signal.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/evaluate_cli.h"
#include "edges/exr_io.h"
#include "edges/view_conversion.h"
#include "evaluate/evaluate.h"
#include "format/manifest.h"
#include "generator/hand/database_rig.h"
#include "generator/testset/testset.h"
#include "photo/image_edges.h"
#include "query/searcher.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

std::atomic<bool> g_cancel{false};
void OnSignal(int) { g_cancel = true; }

// SIGINT/SIGTERM set g_cancel for the scope's lifetime.
class CancelOnSignal {
 public:
  CancelOnSignal() {
    g_cancel = false;
    struct sigaction sa {};
    sa.sa_handler = OnSignal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &old_int_);
    sigaction(SIGTERM, &sa, &old_term_);
  }
  ~CancelOnSignal() {
    sigaction(SIGINT, &old_int_, nullptr);
    sigaction(SIGTERM, &old_term_, nullptr);
  }
  CancelOnSignal(const CancelOnSignal&) = delete;
  CancelOnSignal& operator=(const CancelOnSignal&) = delete;

 private:
  struct sigaction old_int_ {};
  struct sigaction old_term_ {};
};

// The generation seed and hand-model hash a database records, if it does (searched in the
// manifest's metadata where the converter puts the plan's config).
const json* FindKey(const json& j, const std::string& key, int depth = 0) {
  if (!j.is_object() || depth > 3) return nullptr;
  if (auto it = j.find(key); it != j.end()) return &*it;
  for (const auto& [k, v] : j.items()) {
    if (const json* found = FindKey(v, key, depth + 1)) return found;
  }
  return nullptr;
}

}  // namespace

int RunTestset(int argc, char** argv) {
  CLI::App app(
      "Plan and render a held-out test set (schemas/testset_config.schema.json): hand shapes "
      "sampled in the PCA shape space plus a share of basic shapes, view directions uniform on "
      "the sphere, random camera rolls. Each view is rendered as a label EXR + sidecar (clean "
      "input) and a photo-like PNG (skin material, lights, plain or --clutter background); "
      "DIR/testset.json holds the ground truth and is written last. Resumable. A config with "
      "\"sequence\" makes test sequences instead: frames of short videos between natural "
      "poses, the view turning, some leaving the picture, with DIR/sequences/sNNN/ folders of "
      "their frames (docs/evaluation.md, Sequences).",
      "handdb testset");
  std::string config_path;
  std::string out;
  bool clutter = false;
  bool forearm = false;
  bool no_photos = false;
  bool quiet = false;
  bool as_json = false;
  int threads = -1;
  TestSetRenderOptions options;
  options.jobs = 2;
  std::string blender;
  app.add_option("config", config_path, "test-set config JSON (e.g. configs/testset-demo.json)")
      ->required();
  app.add_option("--out", out, "test-set directory")->required();
  app.add_flag("--clutter", clutter, "photos on a procedurally textured background");
  app.add_flag("--forearm",
               forearm,
               "photos show a skin-coloured forearm from the wrist out of the frame, as real "
               "photos do (the label renders, the ground truth, stay the hand alone)");
  app.add_flag("--no-photos", no_photos, "label renders only (clean input)");
  app.add_option("-j,--jobs", options.jobs, "parallel Blender processes")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
  app.add_option("--threads", threads, "threads for the ground-truth conversion (-1: all cores)");
  app.add_option("--blender", blender, "Blender executable (default: $HANDDB_BLENDER, else PATH)");
  app.add_flag("-q,--quiet", quiet, "no progress");
  app.add_flag("--json", as_json, "print a JSON summary on stdout");
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;

  auto config = ReadJsonFile(config_path, "testset_config.schema.json");
  if (!config.ok()) return Fail("testset", config.status());
  auto plan = MakeTestSetPlan(*config, config_path, clutter, forearm);
  if (!plan.ok()) return Fail("testset", plan.status());
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) return Fail("testset", Status(StatusCode::kIoError, out + ": " + ec.message()));
  const fs::path plan_path = fs::path(out) / "testset_plan.json";
  if (fs::exists(plan_path)) {
    auto existing = ReadJsonFile(plan_path, "");
    if (!existing.ok()) return Fail("testset", existing.status());
    if (*existing != *plan) {
      return Fail(
          "testset",
          Status(
              StatusCode::kInvalidArgument,
              plan_path.string() +
                  ": holds a different test-set plan (other config, --clutter or --forearm); use "
                  "a new --out directory"));
    }
  } else {
    Status s = WriteJsonFileAtomic(plan_path, *plan);
    if (!s.ok()) return Fail("testset", s);
  }

  CancelOnSignal signals;
  options.blender = blender;
  options.photos = !no_photos;
  options.progress = !quiet;
  options.cancel = &g_cancel;
  auto rendered = RenderTestSet(out, options);
  if (!rendered.ok()) return Fail("testset", rendered.status());
  Status truth = WriteTestSetGroundTruth(out, threads, !quiet);
  if (!truth.ok()) return Fail("testset", truth);
  const size_t count = plan->at("items").size();
  if (as_json) {
    json j = {{"out", out},
              {"views", count},
              {"units", rendered->units_total},
              {"units_rendered", rendered->units_rendered},
              {"units_skipped", rendered->units_skipped},
              {"photos", !no_photos},
              {"clutter", plan->at("photo").at("clutter")},
              {"forearm", plan->at("photo").value("forearm", false)},
              {"render_seconds", rendered->seconds}};
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!quiet) {
    std::fprintf(stderr,
                 "testset: %zu views in %u units (%u rendered, %u already done) in %.1f s; "
                 "ground truth %s\n",
                 count,
                 rendered->units_total,
                 rendered->units_rendered,
                 rendered->units_skipped,
                 rendered->seconds,
                 (fs::path(out) / "testset.json").c_str());
  }
  return kExitOk;
}

void EvaluateFlags::Add(CLI::App& app) {
  app.add_option("--input",
                 input,
                 "a test view's query: its clean label render or its photo; with --photos the kind "
                 "of picture (auto, photo, edges or labels; default auto, as handdb query)")
      ->check(CLI::IsMember({"clean", "photo", "auto", "edges", "labels"}))
      ->capture_default_str();
  app.add_option("--threads", options.num_threads, "search threads (-1: all cores)")
      ->capture_default_str();
  app.add_option("--fit",
                 fit,
                 "fit the matches' poses to the picture as handdb query --fit does and report "
                 "the fitted answer's 3D keypoint error (auto: --input photo, when the database "
                 "carries its rig; on: also --input clean, fitted to the label render's "
                 "silhouette and edges)")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->capture_default_str();
  app.add_option("--search",
                 search,
                 "exact: every (view, roll) pair; indexed: candidates from the database's index, "
                 "then exact D_c of those only; auto: indexed when the database has an index "
                 "(as handdb query)")
      ->check(CLI::IsMember({"auto", "exact", "indexed"}))
      ->capture_default_str();
  app.add_option(
         "--d", options.correctness.max_joint_distance_deg, "joint distance threshold d (deg)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--distance", distance, "joint distance: rms, max or mean of the 20 differences")
      ->check(CLI::IsMember({"rms", "max", "mean"}))
      ->capture_default_str();
  app.add_option(
         "--max-direction", options.correctness.max_direction_deg, "view direction threshold (deg)")
      ->check(CLI::Range(0.0, 180.0))
      ->capture_default_str();
  app.add_option("--max-roll", options.correctness.max_roll_deg, "roll threshold (deg)")
      ->check(CLI::Range(0.0, 180.0))
      ->capture_default_str();
  app.add_option("--roll-compare", roll_compare, "aligned (cameras) or label (camera_roll values)")
      ->check(CLI::IsMember({"aligned", "label"}))
      ->capture_default_str();
  app.add_flag(
      "--same-shape",
      options.correctness.same_shape,
      "main criterion: basic-shape test views need the same basic shape (the paper's rule)");
  app.add_option("--first-k", options.first_k, "depth of the timed search")
      ->check(CLI::Range(10, 100000))
      ->capture_default_str();
  app.add_option("--max-rank", options.max_rank, "exact ranks up to this depth")
      ->check(CLI::Range(10, 1000000))
      ->capture_default_str();
  app.add_option("--stride", options.stride, "evaluate every K-th test view (a spread-out subset)")
      ->check(CLI::PositiveNumber);
  app.add_option("--limit", options.max_views, "evaluate only the first N (selected) test views")
      ->check(CLI::NonNegativeNumber);
}

bool EvaluateFlags::Finish(const std::string& cmd, bool quiet) {
  if (input != "clean" && input != "photo") {
    std::fprintf(stderr,
                 "handdb %s: --input %s: a test view is queried from its clean label render or "
                 "its photo (--input clean|photo)\n",
                 cmd.c_str(),
                 input.c_str());
    return false;
  }
  options.correctness.joint_distance = *ParseJointDistanceKind(distance);
  options.correctness.roll_compare =
      roll_compare == "aligned" ? RollCompare::kAligned : RollCompare::kLabel;
  options.progress = !quiet;
  if (options.max_rank < options.first_k) {
    std::fprintf(stderr, "handdb %s: --max-rank must be at least --first-k\n", cmd.c_str());
    return false;
  }
  if (query_input() == QueryInput::kPhoto) {
    if (!ResolveLandmarker("auto", cmd, &landmarker)) {
      failure_exit_code = kExitError;
      return false;
    }
    options.landmark_model = landmarker ? landmarker->path().string() : "";
    options.landmark_rank.enabled = landmarker != nullptr;
  }
  return true;
}

bool EvaluateFlags::LoadFit(const fs::path& db_dir, const std::string& cmd) {
  // A clean label render has no landmarks: its fit (silhouette and edges alone) is asked for.
  if (fit == "off" || (query_input() != QueryInput::kPhoto && fit != "on")) return true;
  options.fit.use_silhouette = fit == "on";
  auto rig = LoadDatabaseRig(db_dir);
  if (rig.ok()) {
    options.fit_rig = std::make_shared<const DatabaseRig>(std::move(rig).value());
    return true;
  }
  if (fit == "on") {
    std::fprintf(stderr, "handdb %s: %s\n", cmd.c_str(), rig.status().message().c_str());
    return false;
  }
  return true;  // auto: no fitted row without the rig
}

std::vector<std::string> EvaluateFlags::Args() const {
  auto exact = [](double v) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.17g", v);
    return std::string(buf);
  };
  const CorrectnessOptions& c = options.correctness;
  std::vector<std::string> args = {"--input",
                                   input,
                                   "--fit",
                                   fit,
                                   "--d",
                                   exact(c.max_joint_distance_deg),
                                   "--distance",
                                   std::string(JointDistanceKindName(c.joint_distance)),
                                   "--max-direction",
                                   exact(c.max_direction_deg),
                                   "--max-roll",
                                   exact(c.max_roll_deg),
                                   "--roll-compare",
                                   c.roll_compare == RollCompare::kAligned ? "aligned" : "label",
                                   "--first-k",
                                   std::to_string(options.first_k),
                                   "--max-rank",
                                   std::to_string(options.max_rank),
                                   "--stride",
                                   std::to_string(options.stride),
                                   "--limit",
                                   std::to_string(options.max_views)};
  if (c.same_shape) args.push_back("--same-shape");
  args.insert(args.end(), {"--search", search});
  return args;
}

SearcherOptions EvaluateFlags::searcher_options() const {
  SearcherOptions open;
  open.num_threads = options.num_threads;
  open.use_index = ParseIndexUse(search).value();
  return open;
}

Result<QueryPointsFn> MakeQueryPointsFn(QueryInput input,
                                        const fs::path& db_dir,
                                        const Database& db,
                                        std::shared_ptr<const HandLandmarker> landmarker) {
  if (input == QueryInput::kClean) {
    // The label render through the database's own conversion (edges, normalisation): the edge
    // options its manifest records (conversion.edges), else the defaults. From the manifest the
    // searched shards were opened with (a convert may have replaced manifest.json since).
    std::string fallback;
    auto recorded = DatabaseViewConversionFromMetadata(
        json::parse(db.manifest_metadata_json()), (db_dir / kManifestFileName).string(), &fallback);
    if (!recorded.ok()) return recorded.status();
    if (!fallback.empty()) {
      std::fprintf(stderr,
                   "handdb evaluate: warning: %s; clean queries use the default edge options\n",
                   fallback.c_str());
    }
    const ViewConversionOptions view_options = *recorded;
    return QueryPointsFn([view_options](const TestView& view) -> Result<TestQuery> {
      auto image = ReadLabelExr(view.label, ExrReadOptions{});
      if (!image.ok()) return image.status();
      auto converted =
          LabelImageToPoints(*image, view_options, BorderContact::kReject, view.label.string());
      if (!converted.ok()) return converted.status();
      // The render as a label picture (its points and silhouette), which --fit on fits.
      QueryEdges edges;
      edges.kind = QueryInputKind::kLabels;
      edges.width = image->width;
      edges.height = image->height;
      edges.centre_x = converted->normalisation.centre_x;
      edges.centre_y = converted->normalisation.centre_y;
      edges.diameter_px = converted->normalisation.diameter;
      edges.scale = converted->normalisation.scale;
      for (const EdgePixel& p : converted->edges.silhouette) {
        edges.contour_pixels.push_back({p.col, p.row});
      }
      edges.points = std::move(converted->points);
      return TestQuery(PictureEvidence(std::move(edges)));
    });
  }
  // The photo through the real-image path: skin segmentation, Canny, the same normalisation.
  return QueryPointsFn([landmarker](const TestView& view) -> Result<TestQuery> {
    if (view.photo.empty()) {
      return Status(StatusCode::kNotFound,
                    "test view " + std::to_string(view.id) +
                        ": no photo (the test set was made with --no-photos)");
    }
    PictureOptions picture_options;
    picture_options.edges.kind = QueryInputKind::kPhoto;
    picture_options.landmarker = landmarker;
    auto picture = ReadPicture(view.photo, picture_options);
    if (!picture.ok()) return picture.status();
    return TestQuery(std::move(picture).value());
  });
}

void WarnIfTestSetMatchesDatabase(const fs::path& db_dir, const TestSet& testset) {
  auto manifest = ReadManifest(db_dir);
  if (!manifest.ok()) return;
  const json* seed = FindKey(manifest->metadata, "seed");
  if (seed != nullptr && seed->is_number_unsigned() && seed->get<uint64_t>() == testset.seed) {
    std::fprintf(stderr,
                 "handdb evaluate: warning: the test set and the database share seed %llu\n",
                 static_cast<unsigned long long>(testset.seed));
  }
  const json* sha = FindKey(manifest->metadata, "hand_model_sha256");
  if (sha != nullptr && sha->is_string() && sha->get<std::string>() != testset.hand_model_sha256) {
    std::fprintf(stderr,
                 "handdb evaluate: warning: the test set was rendered with another hand model "
                 "(sha256 %s) than the database (%s)\n",
                 testset.hand_model_sha256.c_str(),
                 sha->get<std::string>().c_str());
  }
}

int RunEvaluate(int argc, char** argv) {
  CLI::App app(
      "Score a database on a held-out test set: the paper's Table 1 (rank of the highest-ranking "
      "correct match in 1, 2-4, 5-16, 17-64, 65-256, 257-1024, >1024), success@(d, n) for n = 1, "
      "10, 100, root-relative 3D keypoint error of the top-1 match and the best of the top 10, "
      "and queries per second. A match is correct when its joint vector is within d of the truth, "
      "its view direction within 30 deg and its roll within 30 deg (docs/evaluation.md). With "
      "--slurm the test views are split over a Slurm job array and the parts merged into the same "
      "report (docs/cluster.md). With --photos DIR instead of TESTSET: shape accuracy on real "
      "photos in DIR/<shape name>/*.jpg|png (top-1/5/10 against a chance baseline, per-shape "
      "table, confusion matrix, contact sheets), searched as --hand right, left or either, with "
      "the photo flags of handdb query; --keypoints FILE adds the 2D keypoint error on annotated "
      "photos; --slurm splits the photos over a job array the same way. A test set of sequences "
      "(handdb testset with a \"sequence\" config) is scored per frame from its photos, "
      "answered by the tracker of handdb track (--predictor alone: each frame alone): keypoint "
      "error, jitter, recovery after the hand left the picture, frames/s.",
      "handdb evaluate");
  // Bound to the request of a Slurm run; a local run reads the same fields.
  EvaluateSlurmRequest request;
  const std::string& db_dir = request.db;
  const std::string& testset_path = request.testset;
  const std::string& json_out = request.json_out;
  const std::string& plots_dir = request.plots_dir;
  EvaluateFlags& flags = request.flags;
  const bool& quiet = request.quiet;
  SlurmFlags slurm;
  app.add_option("db", request.db, "database directory (manifest.json + shards)")->required();
  app.add_option("testset", request.testset, "test-set directory (or its testset.json)");
  PhotoEvaluateRequest photos;
  AddPhotoEvaluateFlags(app, &photos);
  app.add_option("--json",
                 request.json_out,
                 "write the full report (schemas/evaluation.schema.json; with --photos "
                 "photo_evaluation.schema.json)");
  app.add_option(
      "--plots", request.plots_dir, "write PNG plots and example sheets into this directory");
  flags.Add(app);
  SequenceEvaluateFlags sequence_flags;
  sequence_flags.Add(app);
  app.add_flag("-q,--quiet", request.quiet, "no progress, no text report");
  slurm.Add(app);
  const char* group = "Slurm (docs/cluster.md)";
  app.add_option("--tasks",
                 request.tasks,
                 "array tasks (default: one per 16 test views or photos, at most 1000)")
      ->check(CLI::Range(1, 100000))
      ->group(group);
  app.add_option("--work",
                 request.work,
                 "directory for parts, scripts and logs (default: "
                 "TESTSET/slurm-evaluations/<fingerprint>; with --photos "
                 "./slurm-evaluations/<fingerprint>)")
      ->group(group);
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  if (!photos.flags.dir.empty()) {
    if (!CheckPhotoEvaluateUsage(app, request.testset)) return kExitUsage;
    photos.db = request.db;
    photos.json_out = request.json_out;
    photos.quiet = request.quiet;
    photos.tasks = request.tasks;
    photos.work = request.work;
    // --input is this command's own option: a test view's input, or with --photos the kind of
    // picture (default auto, not clean).
    if (app.get_option("--input")->count() > 0) photos.flags.picture.input = flags.input;
    if (!photos.flags.Finish("evaluate", flags.options.num_threads, quiet)) {
      return photos.flags.picture.failure_exit_code;
    }
    if (!slurm.enabled && (request.tasks != 0 || !request.work.empty())) {
      std::fprintf(stderr, "handdb evaluate: --tasks and --work need --slurm\n");
      return kExitUsage;
    }
    if (slurm.enabled) return RunEvaluatePhotosOnSlurm(photos, slurm);
    return RunEvaluatePhotos(photos);
  }
  if (testset_path.empty()) {
    std::fprintf(stderr, "handdb evaluate: give a TESTSET or --photos DIR (see --help)\n");
    return kExitUsage;
  }
  if (!CheckTestSetEvaluateUsage(app)) return kExitUsage;
  // A test set of sequences is scored as sequences (an unreadable one fails below, as any).
  if (auto sequences = IsSequenceTestSet(testset_path); sequences.ok() && *sequences) {
    if (slurm.enabled) {
      std::fprintf(stderr, "handdb evaluate: a sequence test set is scored locally (no --slurm)\n");
      return kExitUsage;
    }
    return RunEvaluateSequences(request, sequence_flags, app.get_option("--input")->count() > 0);
  }
  if (!flags.Finish("evaluate", quiet)) return flags.failure_exit_code;
  if (!slurm.enabled && (request.tasks != 0 || !request.work.empty())) {
    std::fprintf(stderr, "handdb evaluate: --tasks and --work need --slurm\n");
    return kExitUsage;
  }
  if (slurm.enabled) return RunEvaluateOnSlurm(request, slurm);

  auto testset = ReadTestSet(testset_path);
  if (!testset.ok()) return Fail("evaluate", testset.status());
  auto searcher = Searcher::Open(db_dir, flags.searcher_options());
  if (!searcher.ok()) return Fail("evaluate", searcher.status());
  WarnIfTestSetMatchesDatabase(db_dir, *testset);
  if (!flags.LoadFit(db_dir, "evaluate")) return kExitError;

  const QueryInput query_input = flags.query_input();
  auto points_fn =
      MakeQueryPointsFn(query_input, db_dir, (*searcher)->database(), flags.landmarker);
  if (!points_fn.ok()) return Fail("evaluate", points_fn.status());
  if (Status s =
          CheckTestSetInputs(*testset, query_input, SelectTestViews(*testset, flags.options));
      !s.ok()) {
    return Fail("evaluate", s);
  }
  auto report = Evaluate(**searcher, *testset, query_input, *points_fn, flags.options);
  if (!report.ok()) return Fail("evaluate", report.status());
  if (!quiet) std::printf("%s", ReportToText(*report).c_str());
  if (!json_out.empty()) {
    const json doc = ReportToJson(*report);
    Status s = ValidateJson(doc, "evaluation.schema.json", json_out);
    if (s.ok()) s = WriteJsonFileAtomic(json_out, doc);
    if (!s.ok()) return Fail("evaluate", s);
  }
  if (!plots_dir.empty()) {
    Status s = WriteReportPlots(*report, **searcher, *testset, plots_dir);
    if (!s.ok()) return Fail("evaluate", s);
  }
  return kExitOk;
}

}  // namespace handdb::cli
