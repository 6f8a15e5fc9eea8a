// Evaluation end to end with the real Blender (CTest label `blender`): a tiny database
// (`handdb generate`: 2 basic shapes x 12 directions x 8 rolls, 128 px), a tiny rendered test set
// whose first two views are database views (shape, direction, roll of the grid) and whose others
// are held-out samples, then `handdb evaluate` with clean and photo input. Checks: Table 1 adds up
// to the number of test views for every criterion, the database views are found at rank 1 with
// near-zero keypoint error, the report matches its schema, and the CLI's one-line errors.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "base/json_schema.h"
#include "base/testing.h"
#include "generator/plan/plan.h"
#include "generator/testset/testset.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr int kRolls = 8;

using handdb::testing::CliRun;

// `handdb ARGS`, stdout and stderr captured.
CliRun Handdb(const std::string& args) {
  return handdb::testing::RunShell(std::string(HANDDB_BINARY) + " " + args);
}

bool HaveBlender() { return std::system("command -v blender >/dev/null 2>&1") == 0; }

class EvaluateE2E : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!HaveBlender()) return;
    dir_ =
        new fs::path(fs::temp_directory_path() / ("handdb-eval-e2e-" + std::to_string(getpid())));
    fs::remove_all(*dir_);
    fs::create_directories(*dir_);
    const fs::path root = RepoRoot();

    // The database.
    const json db_config = {
        {"name", "eval-e2e"},
        {"seed", 5},
        {"hand_model", (root / "configs/hands/webxr_generic_right.json").string()},
        {"shapes",
         {{"method", "basic"},
          {"library", (root / "configs/shapes/basic.json").string()},
          {"names", {"flat", "fist"}}}},
        {"views", {{"method", "icosahedron"}, {"count", 12}}},
        {"rolls", kRolls},
        {"unit_size", 12},
        {"render", {{"resolution", 128}}}};
    ASSERT_TRUE(WriteJsonFileAtomic(*dir_ / "db.json", db_config).ok());
    const CliRun gen = Handdb("generate " + (*dir_ / "db.json").string() + " -o " +
                              (*dir_ / "db").string() + " -j 2 -q");
    ASSERT_EQ(gen.code, 0) << gen.err;

    // The test set: a planned one whose first two items are replaced by database views.
    const json ts_config = {
        {"format", "handdb-testset-config"},
        {"version", 1},
        {"name", "eval-e2e"},
        {"seed", 77},
        {"count", 5},
        {"basic_fraction", 0.4},
        {"hand_model", (root / "configs/hands/webxr_generic_right.json").string()},
        {"shapes", (root / "configs/shapes/basic.json").string()},
        {"render", {{"resolution", 128}}},
        {"photo", {{"samples", 4}}},
        {"unit_size", 3}};
    auto plan = MakeTestSetPlan(ts_config, *dir_ / "ts.json", false);
    ASSERT_TRUE(plan.ok()) << plan.status().ToString();
    auto db_plan = ReadPlan(*dir_ / "db" / "render" / "plan.json");
    ASSERT_TRUE(db_plan.ok()) << db_plan.status().ToString();
    struct GridView {
      uint32_t shape, dir, roll;
    };
    const GridView grid[2] = {{0, 3, 3}, {1, 7, 6}};
    for (int i = 0; i < 2; ++i) {
      json& item = (*plan)["items"][i];
      const PlanShape& shape = db_plan->shapes[grid[i].shape];
      const PlanDirection& dir = db_plan->directions[grid[i].dir];
      item["basic"] = true;
      item["shape_name"] = shape.name;
      item["joints"] = shape.joints;
      item["coeffs"] = json::array();
      item["clamped"] = false;
      item["direction"] = dir.direction;
      item["theta"] = dir.theta;
      item["phi"] = dir.phi;
      item["roll"] = 2 * M_PI * grid[i].roll / kRolls;
      expected_view_[i] = grid[i].shape * 12 + grid[i].dir;  // one shard order = render order
      expected_roll_[i] = grid[i].roll;
    }
    ASSERT_TRUE(ParseTestSetPlan(*plan, "e2e plan").ok());
    fs::create_directories(*dir_ / "ts");
    ASSERT_TRUE(WriteJsonFileAtomic(*dir_ / "ts" / "testset_plan.json", *plan).ok());
    TestSetRenderOptions render;
    render.jobs = 2;
    render.progress = false;
    auto rendered = RenderTestSet(*dir_ / "ts", render);
    ASSERT_TRUE(rendered.ok()) << rendered.status().ToString();
    ASSERT_EQ(rendered->units_rendered, 2u);
    ASSERT_TRUE(WriteTestSetGroundTruth(*dir_ / "ts", 2, false).ok());
  }
  static void TearDownTestSuite() {
    if (dir_ != nullptr) fs::remove_all(*dir_);
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    if (!HaveBlender()) GTEST_SKIP() << "blender not on PATH";
  }

  json Evaluate(const std::string& input) {
    const fs::path out = *dir_ / ("eval-" + input + ".json");
    const CliRun r = Handdb("evaluate " + (*dir_ / "db").string() + " " + (*dir_ / "ts").string() +
                            " --input " + input + " --json " + out.string() + " --plots " +
                            (*dir_ / ("plots-" + input)).string() + " --threads 2 -q");
    EXPECT_EQ(r.code, 0) << r.err;
    auto doc = ReadJsonFile(out, "evaluation.schema.json");
    EXPECT_TRUE(doc.ok()) << doc.status().ToString();
    return doc.ok() ? *doc : json();
  }

  static fs::path* dir_;
  static uint32_t expected_view_[2];
  static uint32_t expected_roll_[2];
};
fs::path* EvaluateE2E::dir_ = nullptr;
uint32_t EvaluateE2E::expected_view_[2];
uint32_t EvaluateE2E::expected_roll_[2];

void ExpectTablesAddUp(const json& report, size_t views, size_t basic_views) {
  for (const auto& t : report["rank_tables"]) {
    int64_t sum = 0;
    for (const auto& c : t["counts"]) sum += c.get<int64_t>();
    EXPECT_EQ(sum, t["total"].get<int64_t>());
    const size_t expected = t["criterion"] == "same-shape" ? basic_views : views;
    EXPECT_EQ(t["total"].get<size_t>(), expected) << t["criterion"];
  }
}

TEST_F(EvaluateE2E, CleanInputFindsDatabaseViewsAtRankOne) {
  const json report = Evaluate("clean");
  ASSERT_TRUE(report.is_object());
  ASSERT_EQ(report["views"].size(), 5u);
  ExpectTablesAddUp(report, 5, 2);
  for (int i = 0; i < 2; ++i) {
    const json& v = report["views"][i];
    EXPECT_EQ(v["ranks"][0], 1) << "test view " << i;
    EXPECT_EQ(v["ranks"][1], 1) << "same shape, test view " << i;
    EXPECT_EQ(v["top1"]["view_id"], expected_view_[i]);
    EXPECT_EQ(v["top1"]["roll"], expected_roll_[i]);
    EXPECT_LT(v["top1_keypoint_error"].get<double>(), 0.02);
    EXPECT_LT(v["top1"]["direction_deg"].get<double>(), 0.01);
    EXPECT_LT(v["top1"]["roll_deg"].get<double>(), 0.01);
  }
  EXPECT_EQ(report["failed_inputs"], 0);
  EXPECT_GE(report["rank_tables"][0]["counts"][0].get<int>(), 2);
  EXPECT_TRUE(fs::exists(*dir_ / "plots-clean" / "rank_histogram.png"));
  EXPECT_TRUE(fs::exists(*dir_ / "plots-clean" / "keypoint_error_cdf.png"));
}

TEST_F(EvaluateE2E, PhotoInputGoesThroughTheRealImagePath) {
  const json report = Evaluate("photo");
  ASSERT_TRUE(report.is_object());
  ExpectTablesAddUp(report, 5, 2);
  EXPECT_EQ(report["input"], "photo");
  EXPECT_EQ(report["failed_inputs"], 0) << "the skin segmentation found no hand in a photo";
  for (const auto& v : report["views"]) EXPECT_GT(v["query_points"].get<int>(), 50);
}

TEST_F(EvaluateE2E, ErrorsAreOneLine) {
  CliRun r = Handdb("evaluate " + (*dir_ / "db").string() + " " + (*dir_ / "nope").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(r.err.rfind("handdb evaluate: ", 0), 0u) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  r = Handdb("evaluate " + (*dir_ / "db").string());
  EXPECT_EQ(r.code, 2);
  const fs::path bad = *dir_ / "bad-testset.json";
  ASSERT_TRUE(
      WriteJsonFileAtomic(bad, json{{"format", "handdb-testset-config"}, {"version", 1}}).ok());
  r = Handdb("testset " + bad.string() + " --out " + (*dir_ / "ts2").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("bad-testset.json"), std::string::npos) << r.err;
  // A different config into an existing test-set directory is refused.
  r = Handdb("testset " + (RepoRoot() / "configs/testset-demo.json").string() + " --out " +
             (*dir_ / "ts").string() + " --no-photos");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("different test-set plan"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace handdb
