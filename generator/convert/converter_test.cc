#include "generator/convert/converter.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <thread>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/sha256.h"
#include "base/testing.h"
#include "edges/exr_io.h"
#include "edges/synthetic_hand.h"
#include "format/manifest.h"
#include "format/roll.h"
#include "format/shard_layout.h"
#include "format/shard_reader.h"
#include "format/validator.h"
#include "generator/plan/plan.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// Mean nearest-neighbour distance from a to b (brute force), px.
double DirectedChamfer(const std::vector<Point2f>& a, const std::vector<Point2f>& b) {
  double sum = 0;
  for (const auto& p : a) {
    double best = 1e30;
    for (const auto& q : b) {
      best = std::min(best,
                      static_cast<double>((p.x - q.x) * (p.x - q.x) + (p.y - q.y) * (p.y - q.y)));
    }
    sum += std::sqrt(best);
  }
  return sum / static_cast<double>(a.size());
}

double SymmetricChamfer(const std::vector<Point2f>& a, const std::vector<Point2f>& b) {
  return 0.5 * (DirectedChamfer(a, b) + DirectedChamfer(b, a));
}

std::vector<Point2f> ToPx(const std::vector<PointQ>& pts) {
  std::vector<Point2f> out;
  RollPoints(pts, 0.0f, &out);
  return out;
}

Sidecar SidecarFor(const SyntheticHand& hand) {
  Sidecar s;
  s.resolution = hand.image.width;
  s.keypoints_px = hand.keypoints_px;
  return s;
}

// ---------------------------------------------------------------------------------------------
// Normalisation and roll on single views.

TEST(ConvertView, RotatedInputGivesRotatedPointsAndKeypoints) {
  ViewConversionOptions options;
  SyntheticHandParams base;
  base.bend = {0.1, 0.05, -0.1, 0.0, 0.2};
  base.folded[3] = true;
  const SyntheticHand hand0 = RenderSyntheticHand(base);
  auto view0 = ConvertView(hand0.image, SidecarFor(hand0), options, "angle 0");
  ASSERT_TRUE(view0.ok()) << view0.status().ToString();
  EXPECT_GT(view0->points.size(), 300u);
  for (double angle : {0.25, 1.0, M_PI / 2, 2.2, -0.7, 3.0}) {
    SyntheticHandParams p = base;
    p.angle = angle;
    p.centre_x = 131.3;  // also translated: the normalised frame does not see it
    p.centre_y = 124.6;
    const SyntheticHand hand = RenderSyntheticHand(p);
    auto view = ConvertView(hand.image, SidecarFor(hand), options, "rotated");
    ASSERT_TRUE(view.ok()) << view.status().ToString();
    // Roll expansion (format/roll.h) of the canonical view vs converting the rotated render.
    std::vector<Point2f> rolled;
    RollPoints(view0->points, static_cast<float>(angle), &rolled);
    const double chamfer = SymmetricChamfer(rolled, ToPx(view->points));
    EXPECT_LT(chamfer, 1.0) << "angle " << angle;
    EXPECT_NEAR(view->label.source_diameter_px, view0->label.source_diameter_px, 1.5);
    const ViewLabel rolled_label = RollLabel(view0->label, static_cast<float>(angle));
    for (int k = 0; k < kNumKeypoints; ++k) {
      EXPECT_NEAR(rolled_label.keypoints[k][0], view->label.keypoints[k][0], 1.0) << k;
      EXPECT_NEAR(rolled_label.keypoints[k][1], view->label.keypoints[k][1], 1.0) << k;
    }
  }
}

TEST(ConvertView, ScaleInvariantDiameter192) {
  ViewConversionOptions options;
  std::vector<Point2f> reference;
  for (double scale : {0.7, 1.0, 1.25}) {
    SyntheticHandParams p;
    p.scale = scale;
    p.angle = 0.3;
    const SyntheticHand hand = RenderSyntheticHand(p);
    auto view = ConvertView(hand.image, SidecarFor(hand), options, "scaled");
    ASSERT_TRUE(view.ok());
    EXPECT_NEAR(view->label.scale * view->label.source_diameter_px, 192.0f, 1e-3);
    const auto pts = ToPx(view->points);
    if (reference.empty()) {
      reference = pts;
    } else {
      // Rasterisation at another scale: edges move by up to a pixel or so in the normalised frame.
      EXPECT_LT(SymmetricChamfer(reference, pts), 1.5) << "scale " << scale;
    }
  }
}

TEST(ConvertView, RejectsEmptyAndCroppedViews) {
  ViewConversionOptions options;
  SyntheticHandParams p;
  SyntheticHand hand = RenderSyntheticHand(p);
  std::fill(hand.image.labels.begin(), hand.image.labels.end(), 0);
  auto empty = ConvertView(hand.image, SidecarFor(hand), options, "empty.exr");
  EXPECT_EQ(empty.status().code(), StatusCode::kNoHand);
  EXPECT_NE(empty.status().message().find("empty.exr"), std::string::npos);
  p.centre_y = 40;  // fingers leave the image at the top
  hand = RenderSyntheticHand(p);
  auto cropped = ConvertView(hand.image, SidecarFor(hand), options, "cropped.exr");
  EXPECT_EQ(cropped.status().code(), StatusCode::kOutOfRange);
  EXPECT_NE(cropped.status().message().find("touches the image border"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Whole render directories (synthetic renders laid out exactly as blender_scripts/render.py does).

class ConvertDir : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ =
        handdb::testing::TempDir(std::string("converter_") +
                                 ::testing::UnitTest::GetInstance()->current_test_info()->name());
    run_ = root_ / "run";
    fs::create_directories(run_);
    const json config = {{"seed", 7},
                         {"shapes", {{"method", "basic"}, {"count", 2}}},
                         {"views", {{"method", "fibonacci"}, {"count", 5}}},
                         {"rolls", 8},
                         {"unit_size", 4},
                         {"render", {{"resolution", 256}}}};
    ASSERT_TRUE(WriteFileAtomic(root_ / "config.json", config.dump()).ok());
    ASSERT_TRUE(WritePlanFromConfig(root_ / "config.json", run_ / "plan.json").ok());
    auto plan = ReadPlan(run_ / "plan.json");
    ASSERT_TRUE(plan.ok()) << plan.status().ToString();
    plan_ = std::move(plan).value();
    ASSERT_EQ(plan_.units.size(), 3u);
    for (const PlanUnit& unit : plan_.units) {
      for (const PlanRender& r : unit.renders) WriteRender(unit.id, r, RenderParams(r));
      ASSERT_TRUE(WriteFileAtomic(UnitDir(unit.id) / "DONE", "").ok());
    }
  }
  void TearDown() override { fs::remove_all(root_); }

  fs::path UnitDir(uint32_t unit) const { return run_ / "units" / UnitDirName(unit); }
  fs::path Exr(uint32_t unit, uint32_t render_id) const {
    return UnitDir(unit) / (RenderFileStem(render_id) + ".exr");
  }

  static SyntheticHandParams RenderParams(const PlanRender& r) {
    SyntheticHandParams p;
    p.angle = 0.45 * r.dir_id + 0.2 * r.shape_id;
    p.bend = {0.1 * r.shape_id, 0.05, -0.05 * r.dir_id, 0.0, 0.15};
    p.folded[2] = r.shape_id == 1;
    return p;
  }

  void WriteRender(uint32_t unit, const PlanRender& r, const SyntheticHandParams& params) {
    fs::create_directories(UnitDir(unit));
    const SyntheticHand hand = RenderSyntheticHand(params);
    ASSERT_TRUE(WriteLabelExr(Exr(unit, r.render_id), hand.image).ok());
    const PlanDirection& d = plan_.directions[r.dir_id];
    json kp_px = json::array(), kp_cam = json::array();
    for (const auto& k : hand.keypoints_px) {
      kp_px.push_back({k[0], k[1], k[2]});
      kp_cam.push_back({0.0, 0.0, 0.0});
    }
    const json sidecar = {{"render_id", r.render_id},
                          {"unit", unit},
                          {"shape_id", r.shape_id},
                          {"shape_name", plan_.shapes[r.shape_id].name},
                          {"dir_id", r.dir_id},
                          {"joint_angles", plan_.shapes[r.shape_id].joints},
                          {"view_direction", d.direction},
                          {"view_theta", d.theta},
                          {"view_phi", d.phi},
                          {"camera_roll", 0.0},
                          {"resolution", 256},
                          {"ortho_scale", plan_.ortho_scale},
                          {"keypoints_cam", kp_cam},
                          {"keypoints_px", kp_px},
                          {"blender_version", "synthetic"},
                          {"script_version", "test"},
                          {"hand_model_sha256", plan_.hand_model_sha256}};
    ASSERT_TRUE(
        WriteJsonFileAtomic(UnitDir(unit) / (RenderFileStem(r.render_id) + ".json"), sidecar).ok());
  }

  ConvertOptions Options(int threads) const {
    ConvertOptions o;
    o.num_threads = threads;
    o.progress = false;
    return o;
  }

  std::map<std::string, std::string> ReadDir(const fs::path& dir) const {
    std::map<std::string, std::string> files;
    for (const auto& e : fs::directory_iterator(dir)) {
      if (!e.is_regular_file()) continue;
      files[e.path().filename().string()] = ReadFileToString(e.path()).value();
    }
    return files;
  }

  fs::path root_, run_;
  Plan plan_;
};

TEST_F(ConvertDir, WritesOneShardPerUnitAndTheManifest) {
  const fs::path db = root_ / "db";
  auto summary = ConvertRenderDir(run_, db, Options(2));
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_EQ(summary->units_total, 3u);
  EXPECT_EQ(summary->shards_written, 3u);
  EXPECT_EQ(summary->views, 10u);
  EXPECT_TRUE(summary->skipped.empty());

  auto manifest = ReadManifest(db);
  ASSERT_TRUE(manifest.ok()) << manifest.status().ToString();
  EXPECT_EQ(manifest->rolls, 8u);
  EXPECT_EQ(manifest->num_views, 10u);
  EXPECT_EQ(manifest->num_virtual_views, 80u);
  ASSERT_EQ(manifest->shards.size(), 3u);
  EXPECT_EQ(manifest->metadata["shapes"].size(), 2u);
  // The hand model the views were made with, byte for byte: its sha256 is the recorded one.
  auto copy_sha = Sha256File(db / "hand_model.json");
  ASSERT_TRUE(copy_sha.ok()) << copy_sha.status().ToString();
  EXPECT_EQ(*copy_sha, plan_.hand_model_sha256);
  EXPECT_EQ(manifest->metadata["hand_model"]["sha256"], plan_.hand_model_sha256);
  // What the converter writes passes validate, including the manifest-vs-shard cross-checks.
  const ValidationReport report = ValidatePath(db);
  EXPECT_TRUE(report.ok()) << (report.problems.empty() ? "" : report.problems[0].message);
  uint32_t expected_render = 0;
  for (uint32_t u = 0; u < 3; ++u) {
    EXPECT_EQ(manifest->shards[u].file, ShardFileName(u));
    auto reader = ShardReader::Open(db / ShardFileName(u));
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    ASSERT_TRUE(reader->VerifyChecksums().ok());
    EXPECT_EQ(reader->num_views(), plan_.units[u].renders.size());
    const json meta = json::parse(reader->metadata_json());
    EXPECT_EQ(meta["unit"], u);
    EXPECT_EQ(meta["hand_model"]["joint_limits"].size(), 20u);
    EXPECT_EQ(meta["hand_model"]["sha256"], plan_.hand_model_sha256);
    EXPECT_EQ(meta["blender_version"], "synthetic");
    EXPECT_EQ(meta["generation"]["config"]["seed"], 7);
    EXPECT_EQ(meta["labels"]["joint_angles"]["names"].size(), 20u);
    EXPECT_EQ(meta["labels"]["keypoints"]["names"].size(), 21u);
    for (size_t i = 0; i < reader->num_views(); ++i) {
      const ViewLabel label = reader->label(i);
      const PlanRender& r = plan_.units[u].renders[i];
      EXPECT_EQ(label.render_id, expected_render++);
      EXPECT_EQ(label.shape_id, r.shape_id);
      EXPECT_EQ(label.dir_id, r.dir_id);
      EXPECT_FLOAT_EQ(label.joint_angles[0],
                      static_cast<float>(plan_.shapes[r.shape_id].joints[0]));
      EXPECT_GT(reader->points(i).size(), 300u);
      // The middle fingertip lies on the silhouette: some edge point within 2 px of it.
      const auto pts =
          ToPx(std::vector<PointQ>(reader->points(i).begin(), reader->points(i).end()));
      double best = 1e9;
      for (const auto& p : pts) {
        best = std::min<double>(
            best, std::hypot(p.x - label.keypoints[12][0], p.y - label.keypoints[12][1]));
      }
      EXPECT_LT(best, 8.0 * label.scale) << "view " << i;
    }
  }
}

TEST_F(ConvertDir, RerunKeepsShardsAndOutputIsByteIdentical) {
  const fs::path db = root_ / "db";
  ASSERT_TRUE(ConvertRenderDir(run_, db, Options(2)).ok());
  const auto first = ReadDir(db);
  ASSERT_EQ(first.size(), 5u);  // 3 shards + hand model copy + manifest
  auto again = ConvertRenderDir(run_, db, Options(2));
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->shards_kept, 3u);
  EXPECT_EQ(again->shards_written, 0u);
  EXPECT_EQ(ReadDir(db), first);

  // One thread, no memory budget (every view converted twice), elsewhere: same bytes.
  ConvertOptions o = Options(1);
  o.memory_budget_bytes = 0;
  const fs::path db2 = root_ / "db2";
  ASSERT_TRUE(ConvertRenderDir(run_, db2, o).ok());
  EXPECT_EQ(ReadDir(db2), first);

  // A lost shard and manifest (killed run): only that shard is written again.
  fs::remove(db / ShardFileName(1));
  fs::remove(db / "manifest.json");
  // ... with the temp files a kill -9 leaves behind, and a file that is not ours.
  ASSERT_TRUE(WriteFileAtomic(db / (ShardFileName(1) + ".tmp-AbC123"), "partial").ok());
  ASSERT_TRUE(WriteFileAtomic(db / "manifest.json.tmp-x9", "{").ok());
  ASSERT_TRUE(WriteFileAtomic(db / "notes.txt.tmp-1", "keep").ok());
  auto resumed = ConvertRenderDir(run_, db, Options(2));
  ASSERT_TRUE(resumed.ok());
  EXPECT_EQ(resumed->shards_kept, 2u);
  EXPECT_EQ(resumed->shards_written, 1u);
  EXPECT_TRUE(fs::exists(db / "notes.txt.tmp-1"));
  fs::remove(db / "notes.txt.tmp-1");
  EXPECT_EQ(ReadDir(db), first);

  // A damaged shard is not kept.
  {
    std::fstream f(db / ShardFileName(2), std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(300);
    f.put('\x5a');
  }
  auto repaired = ConvertRenderDir(run_, db, Options(2));
  ASSERT_TRUE(repaired.ok());
  EXPECT_EQ(repaired->shards_written, 1u);
  EXPECT_EQ(ReadDir(db), first);
}

TEST_F(ConvertDir, DifferentOptionsRewriteShards) {
  const fs::path db = root_ / "db";
  ASSERT_TRUE(ConvertRenderDir(run_, db, Options(2)).ok());
  const auto with_occlusion = ReadDir(db);
  ConvertOptions off = Options(2);
  off.edges.occlusion_edges = false;
  auto s = ConvertRenderDir(run_, db, off);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->shards_written, 3u);
  // Shape 1 has a folded finger: without occlusion edges its views have fewer points.
  EXPECT_LT(s->points, ConvertRenderDir(run_, root_ / "db_on", Options(2))->points);
  EXPECT_NE(ReadDir(db), with_occlusion);

  // The manifest records the options; a query reads them back (handdb evaluate).
  for (const auto& [dir, occlusion] : {std::pair{db, false}, std::pair{root_ / "db_on", true}}) {
    auto manifest = ReadManifest(dir);
    ASSERT_TRUE(manifest.ok());
    auto read = ViewConversionOptionsFromMetadata(manifest->metadata, dir.string());
    ASSERT_TRUE(read.ok()) << read.status().ToString();
    EXPECT_EQ(read->edges.occlusion_edges, occlusion);
    EXPECT_EQ(read->edges.depth_jump, EdgeOptions{}.depth_jump);
    EXPECT_EQ(read->joint_pairs.size(), 15);
    EXPECT_TRUE(read->joint_pairs.Contains(1, 5));
    EXPECT_FALSE(read->joint_pairs.Contains(5, 8));
  }
}

// What a reader opening DB while a convert rewrites it gets: the manifest and
// the shards of one database, each listed shard present with exactly its listed bytes, and the
// edge options the shards were made with equal to the manifest's. "" when so, else the problem.
std::string ReadConsistentSnapshot(const fs::path& db) {
  return ReadWithStableManifest(db, [&]() -> std::string {
    auto manifest = ReadManifest(db);
    if (!manifest.ok()) return manifest.status().ToString();
    const json& recorded = manifest->metadata["conversion"]["edges"]["occlusion_edges"];
    for (const ManifestShard& entry : manifest->shards) {
      auto reader = ShardReader::Open(db / entry.file);
      if (!reader.ok()) return reader.status().ToString();
      const auto bytes = reader->bytes();
      if (bytes.size() != entry.bytes ||
          shard::ChecksumHex(shard::Checksum(bytes.data(), bytes.size())) != entry.xxh3) {
        return entry.file + ": bytes differ from the manifest's entry";
      }
      const json meta = json::parse(reader->metadata_json());
      if (meta["conversion"]["edges"]["occlusion_edges"] != recorded) {
        return entry.file + ": made with other edge options than the manifest records";
      }
    }
    return "";
  });
}

// A convert that removed a database's manifest before rewriting it would fail a query meanwhile
// with "no such file"; rewriting shards under their listed names instead would show an old
// manifest over new shards. Every rewrite (all three shards change with the
// edge options) is invisible to a reader polling the database: it always finds one complete
// database, old or new, and validate passes throughout.
TEST_F(ConvertDir, ReadersSeeTheOldOrTheNewDatabaseDuringARewrite) {
  const fs::path db = root_ / "db";
  ConvertOptions on = Options(2);
  ConvertOptions off = Options(2);
  off.edges.occlusion_edges = false;
  ASSERT_TRUE(ConvertRenderDir(run_, db, on).ok());
  std::atomic<bool> done{false};
  std::atomic<int> reads{0};
  std::atomic<int> validations{0};
  std::atomic<bool> failed{false};
  std::string first_problem;  // written by the reader before `failed`, read after join()
  std::thread reader([&] {
    while (!done.load()) {
      std::string problem = ReadConsistentSnapshot(db);
      if (problem.empty() && reads % 8 == 0) {
        const ValidationReport report = ValidateDatabase(db);
        if (!report.ok()) problem = "validate: " + report.problems[0].message;
        ++validations;
      }
      ++reads;
      if (!problem.empty()) {
        first_problem = problem;
        failed = true;
        return;
      }
    }
  });
  for (int round = 0; round < 6 && !failed; ++round) {
    auto s = ConvertRenderDir(run_, db, round % 2 == 0 ? off : on);
    if (!s.ok()) {  // not ASSERT: the reader thread must be joined first
      ADD_FAILURE() << s.status().ToString();
      break;
    }
    EXPECT_EQ(s->shards_written, 3u);
  }
  done = true;
  reader.join();
  EXPECT_EQ(first_problem, "") << "after " << reads << " reads";
  EXPECT_GT(reads.load(), 6);
  EXPECT_GT(validations.load(), 0);
  // Afterwards: no staging file left, and byte for byte what a fresh convert writes.
  ASSERT_TRUE(ConvertRenderDir(run_, root_ / "fresh", on).ok());
  EXPECT_TRUE(ReadDir(db) == ReadDir(root_ / "fresh"));  // (no byte dump on failure)
}

// A rewrite interrupted between its two manifests, and a per-unit run over a live database: the
// new shard waits under its staging name (the manifest in place still lists the plain name, whose
// bytes stay), validate passes, and the next whole run keeps that shard and ends with plain names.
TEST_F(ConvertDir, StagedShardsAreKeptAndSwappedIn) {
  const fs::path db = root_ / "db";
  ASSERT_TRUE(ConvertRenderDir(run_, db, Options(2)).ok());
  const auto before = ReadDir(db);
  ConvertOptions off = Options(1);
  off.edges.occlusion_edges = false;
  ConvertOptions unit1 = off;
  unit1.units = {1};
  auto s = ConvertRenderDir(run_, db, unit1);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ(s->shards_written, 1u);
  EXPECT_TRUE(fs::exists(db / ShardStagingFileName(1)));
  auto now = ReadDir(db);
  now.erase(ShardStagingFileName(1));
  EXPECT_EQ(now, before);  // the listed files are untouched
  EXPECT_TRUE(ValidateDatabase(db).ok());
  EXPECT_EQ(*FindCompleteShards(run_, db, off), (std::vector<bool>{false, true, false}));

  // The state between the two manifests: the manifest lists the staging file of unit 1.
  auto manifest = ReadManifest(db);
  ASSERT_TRUE(manifest.ok());
  auto staged = ShardReader::Open(db / ShardStagingFileName(1));
  ASSERT_TRUE(staged.ok());
  ManifestShard& entry = manifest->shards[1];
  entry.file = ShardStagingFileName(1);
  entry.views = staged->num_views();
  entry.points = staged->all_points().size();
  entry.bytes = staged->bytes().size();
  entry.xxh3 = shard::ChecksumHex(shard::Checksum(staged->bytes().data(), entry.bytes));
  manifest->UpdateTotals();
  ASSERT_TRUE(WriteManifest(db, *manifest).ok());
  // ... with the plain name already replaced: not a stray shard, the database still validates
  // apart from the other units' edge options, which this test mixed on purpose.
  ASSERT_TRUE(WriteFileAtomic(db / ShardFileName(1), ReadDir(db)[ShardStagingFileName(1)]).ok());
  for (const auto& p : ValidateDatabase(db).problems) {
    EXPECT_EQ(p.message.find("not listed"), std::string::npos) << p.message;
  }

  auto whole = ConvertRenderDir(run_, db, off);
  ASSERT_TRUE(whole.ok()) << whole.status().ToString();
  EXPECT_EQ(whole->shards_kept, 1u);
  EXPECT_EQ(whole->shards_written, 2u);
  EXPECT_FALSE(fs::exists(db / ShardStagingFileName(1)));
  ASSERT_TRUE(ConvertRenderDir(run_, root_ / "fresh", off).ok());
  EXPECT_TRUE(ReadDir(db) == ReadDir(root_ / "fresh"));  // (no byte dump on failure)
  EXPECT_TRUE(ValidateDatabase(db).ok());
}

TEST(ViewConversionOptionsFromMetadata, ReadsAndRejects) {
  nlohmann::json meta = {
      {"conversion",
       {{"edges",
         {{"occlusion_edges", false}, {"depth_jump", 0.01}, {"joint_pairs", {{1, 2}, {2, 3}}}}}}}};
  auto ok = ViewConversionOptionsFromMetadata(meta, "m.json");
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_FALSE(ok->edges.occlusion_edges);
  EXPECT_EQ(ok->edges.depth_jump, 0.01);
  EXPECT_EQ(ok->joint_pairs.size(), 2);
  EXPECT_TRUE(ok->joint_pairs.Contains(3, 2));
  EXPECT_FALSE(ok->joint_pairs.Contains(1, 5));

  auto missing = ViewConversionOptionsFromMetadata(nlohmann::json::object(), "m.json");
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("m.json"), std::string::npos);
  const std::vector<std::pair<std::string, nlohmann::json>> bad_fields = {
      {"/conversion/edges/depth_jump", -1.0},
      {"/conversion/edges/depth_jump", "5mm"},
      {"/conversion/edges/occlusion_edges", "on"},
      {"/conversion/edges/joint_pairs/0/1", 17},
      {"/conversion/edges/joint_pairs/1", {2}},
      {"/conversion/edges", 3}};
  for (const auto& [path, value] : bad_fields) {
    nlohmann::json bad = meta;
    bad[nlohmann::json::json_pointer(path)] = value;
    auto r = ViewConversionOptionsFromMetadata(bad, "m.json");
    EXPECT_EQ(r.status().code(), StatusCode::kBadJson) << path << " = " << value;
  }
}

TEST_F(ConvertDir, BadInputWritesNothingAndNamesEveryFile) {
  // Unit 0: a truncated EXR. Unit 2: a label out of range. Unit 1: a hand touching the border.
  const PlanRender& r0 = plan_.units[0].renders[1];
  fs::resize_file(Exr(0, r0.render_id), fs::file_size(Exr(0, r0.render_id)) / 2);
  const PlanRender& r2 = plan_.units[2].renders[0];
  {
    SyntheticHand hand = RenderSyntheticHand(RenderParams(r2));
    hand.image.labels[128 * 256 + 128] = 17;  // written as the float 17.0, as Blender would
    ASSERT_TRUE(WriteLabelExr(Exr(2, r2.render_id), hand.image).ok());
  }
  const PlanRender& r1 = plan_.units[1].renders[2];
  SyntheticHandParams cropped = RenderParams(r1);
  cropped.centre_x = 30;
  WriteRender(1, r1, cropped);

  const fs::path db = root_ / "db";
  std::vector<SkippedView> bad;
  auto s = ConvertRenderDir(run_, db, Options(2), &bad);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find(Exr(0, r0.render_id).string()), std::string::npos)
      << s.status().message();
  EXPECT_NE(s.status().message().find("and 2 more bad views"), std::string::npos);
  EXPECT_FALSE(fs::exists(db / ShardFileName(0)));
  EXPECT_FALSE(fs::exists(db / ShardFileName(1)));
  EXPECT_FALSE(fs::exists(db / "manifest.json"));
  ASSERT_EQ(bad.size(), 3u);
  EXPECT_EQ(bad[0].render_id, r0.render_id);
  EXPECT_EQ(bad[0].file, "units/u00000/" + RenderFileStem(r0.render_id) + ".exr");
  EXPECT_NE(bad[0].reason.find("truncated"), std::string::npos) << bad[0].reason;
  EXPECT_EQ(bad[1].render_id, r1.render_id);
  EXPECT_NE(bad[1].reason.find("touches the image border"), std::string::npos) << bad[1].reason;
  EXPECT_EQ(bad[2].render_id, r2.render_id);
  EXPECT_NE(bad[2].reason.find("label 17"), std::string::npos) << bad[2].reason;

  // --skip-bad: the rest is converted, the bad views are recorded.
  ConvertOptions skip = Options(2);
  skip.skip_bad = true;
  auto ok = ConvertRenderDir(run_, db, skip);
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(ok->views, 7u);
  auto manifest = ReadManifest(db);
  ASSERT_TRUE(manifest.ok());
  ASSERT_EQ(manifest->skipped.size(), 3u);
  EXPECT_EQ(manifest->skipped[2].file, bad[2].file);
  EXPECT_EQ(manifest->skipped[2].reason, bad[2].reason);
  EXPECT_EQ(manifest->num_views, 7u);
  // Rerun with --skip-bad keeps everything, with the same skipped list.
  auto rerun = ConvertRenderDir(run_, db, skip);
  ASSERT_TRUE(rerun.ok());
  EXPECT_EQ(rerun->shards_kept, 3u);
  EXPECT_EQ(rerun->skipped.size(), 3u);
  // The skipped views the shards record are the manifest's (validate cross-checks them).
  const ValidationReport report = ValidatePath(db);
  EXPECT_TRUE(report.ok()) << (report.problems.empty() ? "" : report.problems[0].message);
  // Without --skip-bad the bad views are still bad: fails, and keeps the database untouched.
  const auto before = ReadDir(db);
  EXPECT_FALSE(ConvertRenderDir(run_, db, Options(2)).ok());
  EXPECT_EQ(ReadDir(db), before);
}

TEST_F(ConvertDir, MissingSidecarAndPlanMismatch) {
  const PlanRender& r = plan_.units[1].renders[0];
  fs::remove(UnitDir(1) / (RenderFileStem(r.render_id) + ".json"));
  const PlanRender& r2 = plan_.units[1].renders[1];
  const fs::path side2 = UnitDir(1) / (RenderFileStem(r2.render_id) + ".json");
  json doc = json::parse(ReadFileToString(side2).value());
  doc["dir_id"] = 99;
  ASSERT_TRUE(WriteJsonFileAtomic(side2, doc).ok());
  std::vector<SkippedView> bad;
  auto s = ConvertRenderDir(run_, root_ / "db", Options(2), &bad);
  ASSERT_FALSE(s.ok());
  ASSERT_EQ(bad.size(), 2u);
  EXPECT_EQ(bad[0].file, "units/u00001/" + RenderFileStem(r.render_id) + ".json");
  EXPECT_NE(bad[1].reason.find("dir_id 99 disagrees with the plan"), std::string::npos)
      << bad[1].reason;
}

TEST_F(ConvertDir, IncompleteUnitIsAnError) {
  fs::remove(UnitDir(2) / "DONE");
  auto s = ConvertRenderDir(run_, root_ / "db", Options(2));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kNotFound);
  EXPECT_NE(s.status().message().find("u00002"), std::string::npos);
  EXPECT_FALSE(fs::exists(root_ / "db" / "manifest.json"));
}

// The Slurm path (handdb unit convert / finalize): units converted one at a time, then a whole
// run writes the manifest; the result equals one whole run byte for byte.
TEST_F(ConvertDir, OneUnitAtATimeEqualsTheWholeRun) {
  const fs::path db = root_ / "db";
  fs::remove(UnitDir(2) / "DONE");
  auto none = FindCompleteShards(run_, db, Options(1));
  ASSERT_TRUE(none.ok()) << none.status().ToString();  // renders need not be complete
  EXPECT_EQ(*none, (std::vector<bool>{false, false, false}));
  for (uint32_t u : {1u, 0u}) {
    ConvertOptions one = Options(1);
    one.units = {u};
    auto s = ConvertRenderDir(run_, db, one);
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    EXPECT_EQ(s->units_total, 1u);
    EXPECT_EQ(s->shards_written, 1u);
    EXPECT_EQ(s->views, plan_.units[u].renders.size());
  }
  EXPECT_FALSE(fs::exists(db / "manifest.json"));
  EXPECT_EQ(*FindCompleteShards(run_, db, Options(1)), (std::vector<bool>{true, true, false}));
  ConvertOptions other_edges = Options(1);
  other_edges.edges.occlusion_edges = false;  // shards made with other options do not count
  EXPECT_EQ(*FindCompleteShards(run_, db, other_edges), (std::vector<bool>{false, false, false}));

  ConvertOptions bad_unit = Options(1);
  bad_unit.units = {3};
  EXPECT_EQ(ConvertRenderDir(run_, db, bad_unit).status().code(), StatusCode::kOutOfRange);
  ConvertOptions unit2 = Options(1);
  unit2.units = {2};
  EXPECT_EQ(ConvertRenderDir(run_, db, unit2).status().code(), StatusCode::kNotFound);
  ASSERT_TRUE(WriteFileAtomic(UnitDir(2) / "DONE", "").ok());
  ASSERT_TRUE(ConvertRenderDir(run_, db, unit2).ok());

  auto final_run = ConvertRenderDir(run_, db, Options(2));
  ASSERT_TRUE(final_run.ok()) << final_run.status().ToString();
  EXPECT_EQ(final_run->shards_kept, 3u);
  const ValidationReport report = ValidatePath(db);
  EXPECT_TRUE(report.ok()) << (report.problems.empty() ? "" : report.problems[0].message);
  ASSERT_TRUE(ConvertRenderDir(run_, root_ / "whole", Options(2)).ok());
  EXPECT_EQ(ReadDir(db), ReadDir(root_ / "whole"));
}

TEST(ConvertOptions, Check) {
  ConvertOptions ok;
  EXPECT_TRUE(ok.Check());
  ConvertOptions bad;
  bad.num_threads = 0;
  EXPECT_FALSE(bad.Check());
}

}  // namespace
}  // namespace handdb
