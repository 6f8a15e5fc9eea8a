#include "generator/plan/plan.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/testing.h"

namespace handdb {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

json SmallConfig() {
  return json::parse(R"({
    "seed": 0,
    "shapes": {"method": "basic", "count": 3},
    "views": {"method": "fibonacci", "count": 20},
    "rolls": 8,
    "unit_size": 16
  })");
}

const fs::path kConfigPath =
    "/nonexistent-dir/config.json";  // relative paths fall back to the repo

TEST(Plan, BuildsUnitsShapeMajor) {
  PlanSummary summary;
  auto doc = MakePlan(SmallConfig(), kConfigPath, &summary);
  ASSERT_TRUE(doc.ok()) << doc.status().message();
  EXPECT_EQ(summary.renders, 60u);
  EXPECT_EQ(summary.views, 480u);
  EXPECT_EQ(summary.units, 4u);  // 16 + 16 + 16 + 12
  auto plan = ParsePlan(*doc, "plan");
  ASSERT_TRUE(plan.ok()) << plan.status().message();
  ASSERT_EQ(plan->units.size(), 4u);
  EXPECT_EQ(plan->units[3].renders.size(), 12u);
  const PlanRender& r = plan->units[1].renders[5];  // render 21 = shape 1, direction 1
  EXPECT_EQ(r.render_id, 21u);
  EXPECT_EQ(r.shape_id, 1u);
  EXPECT_EQ(r.dir_id, 1u);
  EXPECT_EQ(r.roll, 0.0);
  EXPECT_EQ(plan->hand_model_path, "configs/hands/webxr_generic_right.json");
  EXPECT_EQ(plan->hand_model_sha256.size(), 64u);
  EXPECT_EQ(plan->resolution, 256);
  EXPECT_GT(plan->ortho_scale, 0);
  // 20 Fibonacci directions: between the area bound acos(1 - 2/20) = 25.8 deg and 1.5x that.
  const double cover = (*doc)["sampling"]["views"]["covering_radius_deg"].get<double>();
  EXPECT_EQ(cover, summary.covering_radius_deg);
  EXPECT_GT(cover, 25.8);
  EXPECT_LT(cover, 1.5 * 25.8);
  // Per-render seeds differ and seed 0 is an ordinary seed.
  EXPECT_NE(plan->units[0].renders[0].seed, plan->units[0].renders[1].seed);
  EXPECT_NE(plan->units[0].renders[0].seed, 0u);
}

TEST(Plan, SameConfigSameBytesAndTheSeedMatters) {
  json config = SmallConfig();
  config["shapes"] = {{"method", "pca"}, {"components", 4}, {"count", 5}};
  auto a = MakePlan(config, kConfigPath);
  auto b = MakePlan(config, kConfigPath);
  ASSERT_TRUE(a.ok() && b.ok()) << a.status().message();
  EXPECT_EQ(a->dump(2), b->dump(2));
  config["seed"] = 1;
  auto c = MakePlan(config, kConfigPath);
  ASSERT_TRUE(c.ok());
  EXPECT_NE((*a)["shapes"], (*c)["shapes"]);
  EXPECT_EQ((*a)["directions"], (*c)["directions"]);
}

TEST(Plan, WritesAndReadsBack) {
  auto dir = handdb::testing::TempDir("plan_write");
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "config.json", SmallConfig()).ok());
  PlanSummary summary;
  ASSERT_TRUE(WritePlanFromConfig(dir / "config.json", dir / "plan.json", &summary).ok());
  auto first = ReadFileToString(dir / "plan.json");
  ASSERT_TRUE(WritePlanFromConfig(dir / "config.json", dir / "plan2.json").ok());
  auto second = ReadFileToString(dir / "plan2.json");
  ASSERT_TRUE(first.ok() && second.ok());
  EXPECT_EQ(*first, *second);
  auto plan = ReadPlan(dir / "plan.json");
  ASSERT_TRUE(plan.ok()) << plan.status().message();
  EXPECT_EQ(plan->num_renders(), 60u);
  EXPECT_EQ(plan->num_views(), 480u);
}

TEST(Plan, ShippedConfigsPlan) {
  const struct {
    const char* name;
    uint64_t views;
  } configs[] = {{"demo.json", 6 * 42 * 12}, {"paper.json", 107328}};
  for (const auto& c : configs) {
    auto config = ReadJsonFile(RepoRoot() / "configs" / c.name, "config.schema.json");
    ASSERT_TRUE(config.ok()) << config.status().message();
    PlanSummary summary;
    auto doc = MakePlan(*config, RepoRoot() / "configs" / c.name, &summary);
    ASSERT_TRUE(doc.ok()) << doc.status().message();
    EXPECT_EQ(summary.views, c.views) << c.name;
  }
  // pca-large: check the config only (the plan is 20 MB); >= 1M virtual views by construction.
  auto large = ReadJsonFile(RepoRoot() / "configs/pca-large.json", "config.schema.json");
  ASSERT_TRUE(large.ok()) << large.status().message();
  EXPECT_GE((*large)["shapes"]["count"].get<uint64_t>() *
                (*large)["views"]["count"].get<uint64_t>() * (*large)["rolls"].get<uint64_t>(),
            1000000u);
}

TEST(Plan, RejectsBadConfigs) {
  json c = SmallConfig();
  c["views"] = {{"method", "icosahedron"}, {"count", 50}};
  auto r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("10*4^k+2"), std::string::npos) << r.status().message();

  c = SmallConfig();
  c["surprise"] = 1;
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kSchemaViolation);

  c = SmallConfig();
  c["shapes"]["levels"] = 3;  // a grid option on the basic sampler
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("'levels' does not apply"), std::string::npos)
      << r.status().message();

  c = SmallConfig();
  c["hand_model"] = "no/such/hand.json";
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);

  c = SmallConfig();
  c["shapes"] = {{"method", "pca"}, {"components", 4}};  // no count
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);

  // Seed 2^64 is refused, not written into the plan as a float.
  c = SmallConfig();
  c["seed"] = json::parse("18446744073709551616");
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find(
                "seed 1.8446744073709552e+19 is not an integer in 0..18446744073709551615"),
            std::string::npos)
      << r.status().message();
  c["seed"] = json::parse("18446744073709551615");
  EXPECT_TRUE(MakePlan(c, kConfigPath).ok());
}

// {"method": "pairs", "k": 1000} would make `plan` pass 4 GB in 22 s and a pca count of 10^9
// would be std::bad_alloc. Both are refused from the counts, before sampling, in well under 1 s.
TEST(Plan, RefusesMoreRendersThanAPlanMayHoldBeforeSampling) {
  const auto start = std::chrono::steady_clock::now();
  json c = SmallConfig();
  c["shapes"] = {{"method", "pairs"}, {"k", 1000}};
  auto r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find(": shapes: pairs of 26 basic shapes with k = 1000 give "
                                      "325000 shapes x 20 directions, more than the 250000 "
                                      "renders a plan may hold"),
            std::string::npos)
      << r.status().message();
  c["shapes"] = {{"method", "pca"}, {"components", 4}, {"count", 1000000000}};
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("pca count 1000000000 would give 1000000000 shapes x 20"),
            std::string::npos)
      << r.status().message();
  c["shapes"] = {{"method", "grid"}, {"components", 4}, {"levels", 1000}};
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("grid levels would give "), std::string::npos)
      << r.status().message();
  // One shape over: 12,501 x 20 directions = 250,020 renders.
  c["shapes"] = {{"method", "pca"}, {"components", 4}, {"count", 12501}};
  EXPECT_FALSE(MakePlan(c, kConfigPath).ok());
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
}

TEST(Plan, ParseRejectsInconsistentPlans) {
  auto doc = MakePlan(SmallConfig(), kConfigPath);
  ASSERT_TRUE(doc.ok());
  {
    json bad = *doc;
    bad["units"][1]["renders"][3]["render_id"] = 99;
    auto p = ParsePlan(bad, "p.json");
    ASSERT_FALSE(p.ok());
    EXPECT_NE(p.status().message().find("/units/1/renders/3/render_id"), std::string::npos)
        << p.status().message();
  }
  {
    json bad = *doc;
    bad["units"][0]["renders"][0]["joints"][2] = 0.123;
    EXPECT_FALSE(ParsePlan(bad, "p.json").ok());
  }
  {
    json bad = *doc;
    bad["unit_size"] = 8;
    EXPECT_FALSE(ParsePlan(bad, "p.json").ok());
  }
  {
    json bad = *doc;
    bad["units"].erase(bad["units"].begin() + 3);
    auto p = ParsePlan(bad, "p.json");
    ASSERT_FALSE(p.ok());
    EXPECT_NE(p.status().message().find("cover 48 renders"), std::string::npos)
        << p.status().message();
  }
  {
    json bad = *doc;
    bad["units"][0]["renders"][0]["roll"] = 0.5;
    EXPECT_FALSE(ParsePlan(bad, "p.json").ok());
  }
  {
    json bad = *doc;
    bad.erase("directions");
    auto p = ParsePlan(bad, "p.json");
    ASSERT_FALSE(p.ok());
    EXPECT_EQ(p.status().code(), StatusCode::kSchemaViolation);
  }
}

TEST(Plan, FileNames) {
  EXPECT_EQ(UnitDirName(7), "u00007");
  EXPECT_EQ(RenderFileStem(123), "r000123");
  EXPECT_EQ(ResolvePlanPath("/abs/x.json"), fs::path("/abs/x.json"));
  EXPECT_EQ(ResolvePlanPath("configs/x.json"), RepoRoot() / "configs/x.json");
}

// 655,362 icosahedron directions were generated (and their covering radius measured, 210 s)
// before the count was refused; a PCA scale of 1e308 planned coefficients of null; a shapes
// count of 2^32 + 5 planned 5 shapes.
TEST(Plan, CountsAndNumbersAreCheckedFromTheConfig) {
  const auto start = std::chrono::steady_clock::now();
  json c = SmallConfig();
  c["views"] = {{"method", "icosahedron"}, {"subdivisions", 8}};
  auto r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(),
            kConfigPath.string() +
                ": views: icosahedron subdivisions 8 give 655362 directions, more than the "
                "250000 renders a plan may hold");
  c["views"] = {{"method", "icosahedron"}, {"subdivisions", 7}};  // 163842 x 3 shapes
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("give 3 shapes x 163842 directions"), std::string::npos)
      << r.status().message();
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));

  c = SmallConfig();
  c["shapes"] = {{"method", "pca"}, {"components", 4}, {"count", 4}, {"scale", 1e308}};
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find(": shapes: scale 1e+308 gives a coefficient or joint angle "
                                      "that is not finite"),
            std::string::npos)
      << r.status().message();
  c["shapes"] = {{"method", "basic"}, {"count", 4294967301ull}};
  r = MakePlan(c, kConfigPath);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(
      r.status().message().find("shapes.count is 4294967301, not an integer in 0..4294967295"),
      std::string::npos)
      << r.status().message();
}

}  // namespace
}  // namespace handdb
