#include "generator/testset/testset.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "base/json_schema.h"
#include "generator/hand/hand_model.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

fs::path DemoConfigPath() { return RepoRoot() / "configs" / "testset-demo.json"; }

// The demo config with the fields these tests count on pinned (the demo itself may be retuned).
nlohmann::json DemoConfig() {
  auto doc = ReadJsonFile(DemoConfigPath(), "testset_config.schema.json");
  THROW_CHECK_MSG(doc.ok(), doc.status().ToString());
  nlohmann::json config = *doc;
  config["count"] = 24;
  config["unit_size"] = 12;
  config["basic_fraction"] = 0.5;
  config["basic_names"] = {"flat", "fist", "asl-1", "asl-2", "asl-5", "Y"};
  config["pca"] = {{"components", 6}, {"sampling", "gaussian"}, {"scale", 1.0}, {"max_sigma", 2.5}};
  return config;
}

TEST(TestSetPlan, DeterministicAndValid) {
  const nlohmann::json config = DemoConfig();
  auto a = MakeTestSetPlan(config, DemoConfigPath(), false);
  auto b = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(a->dump(), b->dump());
  auto plan = ParseTestSetPlan(*a, "demo");
  ASSERT_TRUE(plan.ok()) << plan.status().ToString();
  EXPECT_EQ(plan->items.size(), config["count"].get<size_t>());
  EXPECT_EQ(plan->num_units(), 2u);  // 24 items, unit_size 12
  EXPECT_EQ(plan->UnitItems(1).front(), 12u);
  EXPECT_FALSE(plan->photo.clutter);
  EXPECT_EQ(plan->forward_axis, (std::array<double, 3>{0, 0, -1}));
}

TEST(TestSetPlan, ItemsMixBasicAndPcaShapesWithinLimits) {
  auto doc = MakeTestSetPlan(DemoConfig(), DemoConfigPath(), false);
  ASSERT_TRUE(doc.ok());
  auto plan = ParseTestSetPlan(*doc, "demo");
  ASSERT_TRUE(plan.ok());
  auto hand = LoadHandModel(RepoRoot() / "configs/hands/webxr_generic_right.json");
  ASSERT_TRUE(hand.ok());
  auto library = LoadShapes(RepoRoot() / "configs/shapes/basic.json", hand->limits());
  ASSERT_TRUE(library.ok());
  // The demo config draws its basic views from the demo database's shapes only (basic_names).
  const nlohmann::json config = DemoConfig();
  std::set<std::string> names;
  for (const auto& n : config.at("basic_names")) names.insert(n.get<std::string>());
  for (const auto& n : names) {
    EXPECT_TRUE(std::any_of(library->begin(), library->end(), [&](const auto& s) {
      return s.name == n;
    })) << n;
  }
  int basic = 0;
  std::map<std::string, int> basic_seen;
  for (const TestSetItem& item : plan->items) {
    if (item.basic) {
      ++basic;
      EXPECT_TRUE(names.count(item.shape_name)) << item.shape_name;
      ++basic_seen[item.shape_name];
      EXPECT_TRUE(item.coeffs.empty());
    } else {
      EXPECT_EQ(item.coeffs.size(), 6u);
      EXPECT_EQ(item.shape_name.rfind("pca-", 0), 0u);
    }
    EXPECT_TRUE(hand->limits().Contains(item.joints, 1e-9)) << item.shape_name;
    EXPECT_NEAR(std::hypot(item.direction[0], item.direction[1], item.direction[2]), 1.0, 1e-12);
    EXPECT_GE(item.roll, 0.0);
    EXPECT_LT(item.roll, 2 * M_PI);
    EXPECT_NEAR(item.theta, std::acos(item.direction[2]), 1e-12);
  }
  EXPECT_EQ(basic, 12);  // round(0.5 * 24)
  // The named shapes are used up evenly before any repeats: 12 views over 6 names, twice each.
  EXPECT_EQ(basic_seen.size(), names.size());
  for (const auto& [name, count] : basic_seen) EXPECT_EQ(count, 2) << name;
}

TEST(TestSetPlan, BasicNamesRestrictTheBasicShapes) {
  nlohmann::json config = DemoConfig();
  config["basic_fraction"] = 0.5;
  config["basic_names"] = {"fist", "flat", "Y"};
  auto doc = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_TRUE(doc.ok()) << doc.status().ToString();
  auto plan = ParseTestSetPlan(*doc, "names");
  ASSERT_TRUE(plan.ok());
  std::map<std::string, int> seen;
  for (const auto& item : plan->items) {
    if (item.basic) ++seen[item.shape_name];
  }
  EXPECT_EQ(seen, (std::map<std::string, int>{{"fist", 4}, {"flat", 4}, {"Y", 4}}));
  config["basic_names"] = {"no-such-shape"};
  EXPECT_FALSE(MakeTestSetPlan(config, DemoConfigPath(), false).ok());
}

TEST(TestSetPlan, DirectionsAndRollsAreUniform) {
  nlohmann::json config = DemoConfig();
  config["count"] = 4000;
  config["basic_fraction"] = 1.0;  // no PCA work needed
  config["unit_size"] = 1000;
  auto doc = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_TRUE(doc.ok());
  auto plan = ParseTestSetPlan(*doc, "uniform");
  ASSERT_TRUE(plan.ok());
  // Uniform on the sphere: each coordinate has mean 0 and variance 1/3; rolls have mean pi.
  std::array<double, 3> mean{};
  std::array<double, 3> var{};
  double roll_mean = 0;
  for (const auto& item : plan->items) {
    for (int c = 0; c < 3; ++c) {
      mean[c] += item.direction[c];
      var[c] += item.direction[c] * item.direction[c];
    }
    roll_mean += item.roll;
  }
  const double n = static_cast<double>(plan->items.size());
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(mean[c] / n, 0.0, 0.04) << "axis " << c;
    EXPECT_NEAR(var[c] / n, 1.0 / 3, 0.03) << "axis " << c;
  }
  EXPECT_NEAR(roll_mean / n, M_PI, 0.1);
}

TEST(TestSetPlan, SeedChangesEverythingAndClutterFlagIsRecorded) {
  nlohmann::json config = DemoConfig();
  auto a = MakeTestSetPlan(config, DemoConfigPath(), false);
  config["seed"] = config["seed"].get<uint64_t>() + 1;
  auto b = MakeTestSetPlan(config, DemoConfigPath(), true);
  ASSERT_TRUE(a.ok() && b.ok());
  auto pa = ParseTestSetPlan(*a, "a");
  auto pb = ParseTestSetPlan(*b, "b");
  ASSERT_TRUE(pa.ok() && pb.ok());
  EXPECT_TRUE(pb->photo.clutter);
  int same_direction = 0;
  for (size_t i = 0; i < pa->items.size(); ++i) {
    same_direction += pa->items[i].direction == pb->items[i].direction ? 1 : 0;
    EXPECT_NE(pa->items[i].seed, pb->items[i].seed);
  }
  EXPECT_EQ(same_direction, 0);
}

TEST(TestSetPlan, ForearmIsWrittenOnlyWhenOn) {
  // Off: the plan has no "forearm" key, so plans of test sets made before the option are
  // byte-identical to what the new code writes (a rerun compares them).
  auto off = MakeTestSetPlan(DemoConfig(), DemoConfigPath(), false);
  ASSERT_TRUE(off.ok());
  EXPECT_FALSE(off->at("photo").contains("forearm"));
  auto poff = ParseTestSetPlan(*off, "off");
  ASSERT_TRUE(poff.ok());
  EXPECT_FALSE(poff->photo.forearm);
  // On from the CLI flag or from the config.
  auto flag = MakeTestSetPlan(DemoConfig(), DemoConfigPath(), false, true);
  nlohmann::json config = DemoConfig();
  config["photo"]["forearm"] = true;
  auto cfg = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_TRUE(flag.ok() && cfg.ok());
  for (const nlohmann::json* doc : {&*flag, &*cfg}) {
    EXPECT_TRUE(doc->at("photo").at("forearm").get<bool>());
    auto parsed = ParseTestSetPlan(*doc, "on");
    ASSERT_TRUE(parsed.ok()) << parsed.status().message();
    EXPECT_TRUE(parsed->photo.forearm);
    EXPECT_FALSE(parsed->photo.clutter);
  }
}

TEST(TestSetPlan, RejectsBadConfigsAndPlans) {
  nlohmann::json config = DemoConfig();
  config["count"] = 0;
  auto bad = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kSchemaViolation);

  config = DemoConfig();
  config["pca"]["components"] = 30;
  EXPECT_FALSE(MakeTestSetPlan(config, DemoConfigPath(), false).ok());

  config = DemoConfig();
  config["shapes"] = "configs/shapes/no-such-file.json";
  bad = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kNotFound);

  auto doc = MakeTestSetPlan(DemoConfig(), DemoConfigPath(), false);
  ASSERT_TRUE(doc.ok());
  nlohmann::json broken = *doc;
  broken["items"][3]["id"] = 7;
  auto parsed = ParseTestSetPlan(broken, "broken.json");
  ASSERT_FALSE(parsed.ok());
  EXPECT_NE(parsed.status().message().find("item 3"), std::string::npos);
  broken = *doc;
  broken["items"][2]["direction"] = {0.0, 0.0, 2.0};
  EXPECT_EQ(ParseTestSetPlan(broken, "broken.json").status().code(), StatusCode::kOutOfRange);
}

TEST(TestSetPlan, FileNames) {
  EXPECT_EQ(TestSetLabelPath("/d", 3, 123), fs::path("/d/units/u00003/r000123.exr"));
  EXPECT_EQ(TestSetSidecarPath("/d", 3, 123), fs::path("/d/units/u00003/r000123.json"));
  EXPECT_EQ(TestSetPhotoPath("/d", 3, 123), fs::path("/d/photos/u00003/r000123.png"));
}

// A seed of 2^64 parsed as a double and was recorded as 0 (the generation config refused it).
TEST(TestSetPlan, SeedBeyondItsTypeIsRefused) {
  nlohmann::json config = DemoConfig();
  config["seed"] = nlohmann::json::parse("18446744073709551616");
  auto bad = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kOutOfRange);
  EXPECT_EQ(bad.status().message(),
            DemoConfigPath().string() +
                ": seed is 1.8446744073709552e+19, not an integer in 0..18446744073709551615");
  config["seed"] = 18446744073709551615ull;
  EXPECT_TRUE(MakeTestSetPlan(config, DemoConfigPath(), false).ok());
}

}  // namespace
}  // namespace handdb
