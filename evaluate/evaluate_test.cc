#include "evaluate/evaluate.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "evaluate/evaluate_testing.h"
#include "query/index/view_index.h"

namespace handdb {
namespace {

EvaluationOptions FastOptions() {
  EvaluationOptions o;
  o.first_k = 10;
  o.num_threads = 1;
  o.progress = false;
  o.success_n = {1, 10};
  return o;
}

TEST(Evaluate, DatabaseViewsAreFoundAtRankOne) {
  auto db = testing::EvalDatabase();
  Searcher searcher(db);
  TestSet set;
  struct Source {
    view_id_t v;
    roll_id_t r;
  };
  std::vector<Source> sources = {{3, 0}, {17, 5}, {29, 11}};
  for (uint32_t i = 0; i < sources.size(); ++i) {
    set.views.push_back(testing::ViewOf(*db, i, sources[i].v, sources[i].r, i == 0));
  }
  auto points = [&](const TestView& t) -> Result<TestQuery> {
    return TestQuery(testing::RolledView(*db, sources[t.id].v, sources[t.id].r));
  };
  auto report = Evaluate(searcher, set, QueryInput::kClean, points, FastOptions());
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  ASSERT_EQ(report->views.size(), 3u);
  for (const auto& v : report->views) {
    EXPECT_EQ(v.ranks[0], 1) << "test " << v.test_id;
    ASSERT_TRUE(v.top1.has_value());
    EXPECT_EQ(v.top1->view_id, sources[v.test_id].v);
    EXPECT_EQ(v.top1->roll, sources[v.test_id].r);
    EXPECT_NEAR(v.top1_keypoint_error, 0.0, 1e-5);
    EXPECT_NEAR(v.best10_keypoint_error, 0.0, 1e-5);
    EXPECT_FALSE(v.deep_search);
    EXPECT_GE(v.num_correct, 1);  // at least the view itself
  }
  ASSERT_EQ(report->chance_success.size(), 2u);
  EXPECT_GT(report->chance_success[0], 0.0);
  EXPECT_LT(report->chance_success[0], report->chance_success[1]);
  EXPECT_LT(report->chance_success[1], 0.5);
  // Table 1 of the main criterion: all three at rank 1; same-shape applies to the basic view only.
  EXPECT_EQ(report->tables[0].counts[0], 3);
  EXPECT_EQ(report->tables[0].total(), 3);
  EXPECT_EQ(report->tables[1].total(), 1);
  EXPECT_EQ(report->views[1].ranks[1], -1);
  EXPECT_EQ(report->success[0].rate, 1.0);
  EXPECT_GT(report->queries_per_second, 0.0);

  const nlohmann::json doc = ReportToJson(*report);
  EXPECT_TRUE(ValidateJson(doc, "evaluation.schema.json", "report").ok());
  EXPECT_NE(ReportToText(*report).find("Table 1"), std::string::npos);
}

TEST(Evaluate, RanksBeyondTheFirstSearchAreExact) {
  auto db = testing::EvalDatabase();
  Searcher searcher(db);
  // Truth: view 5 at roll 2; query: the edges of view 30 at roll 7, so the correct match sits
  // somewhere down the list. The reference: the brute-force ordering of every (view, roll).
  TestSet set;
  set.views.push_back(testing::ViewOf(*db, 0, 5, 2, false));
  const std::vector<Point2f> query = testing::RolledView(*db, 30, 7);
  auto points = [&](const TestView&) -> Result<TestQuery> { return TestQuery(query); };
  EvaluationOptions options = FastOptions();
  auto report = Evaluate(searcher, set, QueryInput::kClean, points, options);
  ASSERT_TRUE(report.ok());

  SearchOptions all;
  all.top_k = static_cast<int>(db->num_virtual_views());
  all.brute_force = true;
  all.num_threads = 1;
  auto reference = searcher.Search(query, all);
  ASSERT_TRUE(reference.ok());
  const auto criteria = MakeCriteria(options);
  CorrectnessJudge judge(set.views[0].truth, false, set.axes, criteria[0].options);
  int64_t expected = kNoCorrectMatch;
  for (size_t i = 0; i < reference->size(); ++i) {
    if (judge.IsCorrect(PoseFromLabel((*reference)[i].label, 0))) {
      expected = static_cast<int64_t>(i) + 1;
      break;
    }
  }
  ASSERT_NE(expected, kNoCorrectMatch);  // view 5 itself is correct
  ASSERT_GT(expected, options.first_k) << "the case must need the deeper search";
  EXPECT_EQ(report->views[0].ranks[0], expected);
  EXPECT_TRUE(report->views[0].deep_search);
  EXPECT_EQ(report->deep_searches, 1);
  EXPECT_EQ(report->tables[0].counts[RankBin(expected)], 1);
}

TEST(Evaluate, UnreachableTruthAndFailedInputsLandInTheLastBin) {
  auto db = testing::EvalDatabase();
  Searcher searcher(db);
  TestSet set;
  set.views.push_back(testing::ViewOf(*db, 0, 8, 0, false));
  for (auto& j : set.views[0].truth.joint_angles) j += 2.0f;  // no database shape is near
  set.views.push_back(testing::ViewOf(*db, 1, 9, 0, true));
  auto points = [&](const TestView& t) -> Result<TestQuery> {
    if (t.id == 1) return Status(StatusCode::kNoHand, "photo: no hand found");
    return TestQuery(testing::RolledView(*db, 8, 0));
  };
  auto report = Evaluate(searcher, set, QueryInput::kPhoto, points, FastOptions());
  ASSERT_TRUE(report.ok());
  EXPECT_EQ(report->views[0].ranks[0], kNoCorrectMatch);
  EXPECT_EQ(report->views[0].num_correct, 0);
  EXPECT_FALSE(report->views[0].deep_search) << "no correct pair exists: nothing to search for";
  EXPECT_EQ(report->views[1].ranks[0], kNoCorrectMatch);
  EXPECT_EQ(report->views[1].error, "photo: no hand found");
  EXPECT_EQ(report->failed_inputs, 1);
  EXPECT_EQ(report->tables[0].counts[kNumRankBins - 1], 2);
  EXPECT_EQ(report->views_without_correct[0], 1);  // the unreachable one, not the failed input
  EXPECT_EQ(report->tables[0].total(), 2);
  EXPECT_TRUE(std::isnan(report->views[1].top1_keypoint_error));
  EXPECT_EQ(report->top1_keypoint_error.count, 1);
  EXPECT_TRUE(ValidateJson(ReportToJson(*report), "evaluation.schema.json", "report").ok());
}

// The exhaustive minimum over every (view, roll), as a search's match labels give them.
double BruteForceFloor(const Database& db, const Keypoints& truth) {
  double best = std::numeric_limits<double>::infinity();
  for (view_id_t v = 0; v < db.num_views(); ++v) {
    for (roll_id_t r = 0; r < db.num_rolls(); ++r) {
      const ViewLabel rolled = RollLabel(db.label(v), RollAngle(r, db.num_rolls()));
      best = std::min(best, KeypointError(truth, rolled.keypoints));
    }
  }
  return best;
}

TEST(KeypointFloor, EqualsTheExhaustiveMinimum) {
  auto db = testing::EvalDatabase();
  std::vector<ViewLabel> labels;
  for (view_id_t v = 0; v < db->num_views(); ++v) labels.push_back(db->label(v));
  const KeypointFloorIndex index(labels, db->num_rolls());
  // A database view's own keypoints: floor 0 at that (view, roll).
  const PoseForEval own = PoseFromLabel(db->label(17), RollAngle(5, db->num_rolls()));
  const KeypointFloor exact = index.Floor(own.keypoints);
  EXPECT_EQ(exact.error, 0.0);
  EXPECT_EQ(exact.view_id, 17u);
  EXPECT_EQ(exact.roll, 5u);
  // Noisy and unrelated truths: the pruned scan equals the exhaustive one, bit for bit, and
  // tries fewer views than there are.
  uint64_t checked = 0;
  for (int t = 0; t < 20; ++t) {
    Keypoints truth = db->label(static_cast<view_id_t>(t)).keypoints;
    for (int k = 0; k < kNumKeypoints; ++k) {
      for (int c = 0; c < 3; ++c) {
        truth[k][c] += static_cast<float>(std::sin(7.1 * t + 3.3 * k + 1.7 * c)) * 8.0f * t;
      }
    }
    const KeypointFloor f = index.Floor(truth);
    EXPECT_EQ(f.error, BruteForceFloor(*db, truth)) << t;
    const ViewLabel at = RollLabel(db->label(f.view_id), RollAngle(f.roll, db->num_rolls()));
    EXPECT_EQ(KeypointError(truth, at.keypoints), f.error) << t;
    checked += f.views_checked;
  }
  EXPECT_LT(checked, 20 * db->num_views());
}

TEST(KeypointFloor, WristToMiddleMcp) {
  Keypoints k{};
  k[0] = {10, 20, 30};
  k[9] = {13, 24, 30};
  EXPECT_DOUBLE_EQ(WristToMiddleMcp(k), 5.0);
}

TEST(Evaluate, FloorAndWristToMiddleMcpUnits) {
  auto db = testing::EvalDatabase();
  Searcher searcher(db);
  TestSet set;
  // Truths off the database (keypoints moved), queried by the edges of a nearby view.
  for (uint32_t i = 0; i < 4; ++i) {
    set.views.push_back(testing::ViewOf(*db, i, 3 + 7 * i, i, false));
    for (auto& kp : set.views.back().truth.keypoints) kp[2] += 5.0f * static_cast<float>(i + 1);
  }
  auto points = [&](const TestView& t) -> Result<TestQuery> {
    return TestQuery(testing::RolledView(*db, 3 + 7 * t.id, t.id));
  };
  auto report = Evaluate(searcher, set, QueryInput::kClean, points, FastOptions());
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  for (const auto& v : report->views) {
    const Keypoints& truth = set.views[v.testset_index].truth.keypoints;
    EXPECT_EQ(v.floor_keypoint_error, BruteForceFloor(*db, truth));
    EXPECT_LE(v.floor_keypoint_error, v.best10_keypoint_error);
    EXPECT_LE(v.best10_keypoint_error, v.top1_keypoint_error);
    EXPECT_EQ(v.wrist_to_middle_mcp_px, WristToMiddleMcp(truth));
    EXPECT_TRUE(std::isnan(v.fitted_keypoint_error));
  }
  EXPECT_EQ(report->floor_keypoint_error.count, 4);
  EXPECT_EQ(report->fitted_keypoint_error.count, 0);
  EXPECT_LE(report->floor_keypoint_error.mean, report->best10_keypoint_error.mean);
  // The same errors in wrist-to-middle-MCP lengths of each truth.
  std::vector<double> wm;
  for (const auto& v : report->views) {
    wm.push_back(v.top1_keypoint_error * kNormalisedDiameter / v.wrist_to_middle_mcp_px);
  }
  EXPECT_DOUBLE_EQ(report->top1_keypoint_error_wm.mean, Summarise(wm).mean);
  EXPECT_DOUBLE_EQ(report->top1_keypoint_error_wm.p90, Summarise(wm).p90);

  nlohmann::json doc = ReportToJson(*report);
  EXPECT_TRUE(ValidateJson(doc, "evaluation.schema.json", "report").ok());
  EXPECT_TRUE(doc["keypoint_error"].contains("floor"));
  EXPECT_FALSE(doc["keypoint_error"].contains("fitted"));
  EXPECT_TRUE(doc["keypoint_error"]["wrist_to_middle_mcp"].contains("floor"));
  EXPECT_DOUBLE_EQ(doc["keypoint_error"]["wrist_to_middle_mcp"]["top1"]["mean"].get<double>(),
                   Summarise(wm).mean);
  const std::string text = ReportToText(*report);
  EXPECT_NE(text.find("floor (best view and roll of the database)"), std::string::npos);
  EXPECT_NE(text.find("wrist-to-middle-MCP lengths"), std::string::npos);
  EXPECT_EQ(text.find("fitted pose"), std::string::npos);

  // The fitted slot: filled by a caller that fits poses, reported in both units.
  for (auto& v : report->views) v.fitted_keypoint_error = 0.5 * v.best10_keypoint_error;
  FinishReport(&*report);
  EXPECT_EQ(report->fitted_keypoint_error.count, 4);
  doc = ReportToJson(*report);
  EXPECT_TRUE(ValidateJson(doc, "evaluation.schema.json", "report").ok());
  EXPECT_TRUE(doc["keypoint_error"].contains("fitted"));
  EXPECT_TRUE(doc["keypoint_error"]["wrist_to_middle_mcp"].contains("fitted"));
  EXPECT_NE(ReportToText(*report).find("fitted pose"), std::string::npos);

  // Without the floor: no floor anywhere.
  EvaluationOptions no_floor = FastOptions();
  no_floor.keypoint_floor = false;
  auto without = Evaluate(searcher, set, QueryInput::kClean, points, no_floor);
  ASSERT_TRUE(without.ok());
  EXPECT_TRUE(std::isnan(without->views[0].floor_keypoint_error));
  EXPECT_EQ(without->floor_keypoint_error.count, 0);
  doc = ReportToJson(*without);
  EXPECT_TRUE(ValidateJson(doc, "evaluation.schema.json", "report").ok());
  EXPECT_FALSE(doc["keypoint_error"].contains("floor"));
  EXPECT_EQ(ReportToText(*without).find("floor ("), std::string::npos);
  EXPECT_EQ(without->views[2].top1_keypoint_error, report->views[2].top1_keypoint_error);
}

// A minimal schema-valid testset.json with one view; `edit` changes it before it is written.
template <typename F>
Result<TestSet> ReadEditedTestSet(const std::string& name, F edit) {
  nlohmann::json item = {
      {"id", 0},
      {"unit", 0},
      {"basic", true},
      {"shape_name", "fist"},
      {"joint_angles", std::vector<double>(20, 0.25)},
      {"view_direction", {0, 0, 1}},
      {"view_theta", 0},
      {"view_phi", 0},
      {"camera_roll", 0},
      {"keypoints", std::vector<std::vector<double>>(21, {1, 2, 3})},
      {"normalisation", {{"centre_px", {128, 128}}, {"diameter_px", 150}, {"scale", 1.28}}},
      {"num_edge_points", 800},
      {"label", "units/u00000/r000000.exr"},
      {"sidecar", "units/u00000/r000000.json"}};
  nlohmann::json doc = {{"format", "handdb-testset"},
                        {"version", 1},
                        {"name", "t"},
                        {"seed", 1},
                        {"plan", "testset_plan.json"},
                        {"hand_model", {{"path", "h.json"}, {"sha256", std::string(64, '0')}}},
                        {"forward_axis", {0, 1, 0}},
                        {"palm_normal", {0, 0, 1}},
                        {"resolution", 256},
                        {"ortho_scale", 0.3},
                        {"clutter", false},
                        {"handdb_version", "test"},
                        {"items", {item}}};
  edit(doc);
  const auto path = std::filesystem::temp_directory_path() /
                    ("handdb-testset-" + name + "-" + std::to_string(::getpid()) + ".json");
  THROW_CHECK(WriteFileAtomic(path, doc.dump()).ok());
  auto set = ReadTestSet(path);
  std::filesystem::remove(path);
  return set;
}

// A seed of 2^64 (parsed as a float) or a joint angle beyond the float range passed the schema
// and was cast with undefined behaviour (tests/fuzz/testset_fuzzer.cc).
TEST(ReadTestSet, RefusesValuesOutsideTheirRange) {
  auto ok = ReadEditedTestSet("ok", [](nlohmann::json&) {});
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  EXPECT_FLOAT_EQ(ok->views[0].truth.joint_angles[3], 0.25f);
  auto seed = ReadEditedTestSet(
      "seed", [](nlohmann::json& d) { d["seed"] = nlohmann::json::parse("18446744073709551616"); });
  ASSERT_FALSE(seed.ok());
  EXPECT_EQ(seed.status().code(), StatusCode::kOutOfRange);
  EXPECT_NE(seed.status().message().find(": seed is 1.8446744073709552e+19, outside its range"),
            std::string::npos)
      << seed.status().message();
  auto angle = ReadEditedTestSet(
      "angle", [](nlohmann::json& d) { d["items"][0]["joint_angles"][3] = 1e300; });
  ASSERT_FALSE(angle.ok());
  EXPECT_NE(
      angle.status().message().find(": items[0].joint_angles[3] is 1e+300, outside its range"),
      std::string::npos)
      << angle.status().message();
  auto id = ReadEditedTestSet("id", [](nlohmann::json& d) { d["items"][0]["id"] = 5000000000ull; });
  ASSERT_FALSE(id.ok());
  EXPECT_NE(id.status().message().find("items[0].id is 5000000000"), std::string::npos);
}

TEST(ChanceBaseline, HypergeometricKnownValues) {
  EXPECT_DOUBLE_EQ(ChanceOfCorrectInTopN(10, 0, 5), 0.0);
  EXPECT_NEAR(ChanceOfCorrectInTopN(10, 1, 1), 0.1, 1e-12);
  EXPECT_NEAR(ChanceOfCorrectInTopN(10, 1, 3), 0.3, 1e-12);
  EXPECT_NEAR(ChanceOfCorrectInTopN(4, 2, 2), 1.0 - (2.0 / 4) * (1.0 / 3), 1e-12);
  EXPECT_DOUBLE_EQ(ChanceOfCorrectInTopN(10, 1, 10), 1.0);
  EXPECT_DOUBLE_EQ(ChanceOfCorrectInTopN(10, 9, 2), 1.0);  // only one wrong item
}

TEST(EvaluationOptions, Check) {
  EvaluationOptions o;
  EXPECT_TRUE(o.Check());
  o.first_k = 5;  // the best of the top 10 needs 10
  EXPECT_FALSE(o.Check());
  o = EvaluationOptions();
  o.max_rank = 50;  // below first_k
  EXPECT_FALSE(o.Check());
  o = EvaluationOptions();
  o.stride = 0;
  EXPECT_FALSE(o.Check());
  o = EvaluationOptions();
  o.success_n = {2000};
  EXPECT_FALSE(o.Check());
}

TEST(Criteria, MainSameShapeAndTheDGrid) {
  EvaluationOptions o;
  o.d_grid_deg = {10, 20};
  const auto c = MakeCriteria(o);
  ASSERT_EQ(c.size(), 4u);
  EXPECT_EQ(c[0].name, "main");
  EXPECT_TRUE(c[1].options.same_shape);
  EXPECT_TRUE(c[1].basic_only);
  EXPECT_EQ(c[2].name, "d=10");
  EXPECT_EQ(c[3].options.max_joint_distance_deg, 20);
}

// Evaluate searches as its Searcher does: with an index attached (SearcherOptions::use_index at
// open), every search is indexed (SearchMode::kAuto), and one built for another database is
// every view's error.
TEST(Evaluate, SearchesWithTheSearchersIndex) {
  auto db = testing::EvalDatabase();
  IndexBuildOptions build;
  build.grid.cell_units = 256;
  build.grid.side = 15;
  build.dims = 16;
  build.nlist = 4;
  build.num_threads = 1;
  TestSet set;
  set.views.push_back(testing::ViewOf(*db, 0, 17, 5, true));
  auto points = [&](const TestView&) -> Result<TestQuery> {
    return TestQuery(testing::RolledView(*db, 17, 5));
  };

  auto index = ViewIndex::Build(*db, build);
  ASSERT_TRUE(index.ok()) << index.status().ToString();
  auto searcher = Searcher::Create(db);
  ASSERT_TRUE(searcher.ok());
  (*searcher)->SetIndex(std::make_shared<const ViewIndex>(std::move(index).value()));
  auto report = Evaluate(**searcher, set, QueryInput::kClean, points, FastOptions());
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_EQ(report->views[0].ranks[0], 1) << report->views[0].error;

  auto other_db = std::make_shared<const Database>(testing::SyntheticDatabase(30, 200, 12, 10));
  auto other = ViewIndex::Build(*other_db, build);
  ASSERT_TRUE(other.ok());
  (*searcher)->SetIndex(std::make_shared<const ViewIndex>(std::move(other).value()));
  report = Evaluate(**searcher, set, QueryInput::kClean, points, FastOptions());
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_NE(report->views[0].error.find("the index is of another database"), std::string::npos)
      << report->views[0].error;
}

}  // namespace
}  // namespace handdb
