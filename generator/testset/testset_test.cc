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

// The demo config with natural poses instead of the shape library.
nlohmann::json NaturalConfig() {
  nlohmann::json config = DemoConfig();
  for (const char* key : {"shapes", "basic_fraction", "basic_names", "pca"}) config.erase(key);
  config["count"] = 60;
  config["unit_size"] = 30;
  config["poses"] = {{"method", "natural"}, {"finger_spread", 0.15}};
  config["photo"]["forearm_fraction"] = 0.5;
  return config;
}

TEST(TestSetPlan, NaturalPosesAreDeterministicWithinLimitsAndFollowTheGrip) {
  auto a = MakeTestSetPlan(NaturalConfig(), DemoConfigPath(), false);
  auto b = MakeTestSetPlan(NaturalConfig(), DemoConfigPath(), false);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(a->dump(), b->dump());
  EXPECT_EQ(a->at("shapes").at("natural").get<int>(), 60);
  EXPECT_FALSE(a->at("shapes").contains("library"));
  auto plan = ParseTestSetPlan(*a, "natural");
  ASSERT_TRUE(plan.ok()) << plan.status().ToString();
  auto hand = LoadHandModel(RepoRoot() / "configs/hands/webxr_generic_right.json");
  ASSERT_TRUE(hand.ok());
  const JointLimits limits = hand->limits();
  int forearms = 0;
  double sum_gap = 0;
  for (const TestSetItem& item : plan->items) {
    EXPECT_FALSE(item.basic);
    EXPECT_EQ(item.shape_name.rfind("natural-", 0), 0u) << item.shape_name;
    EXPECT_TRUE(limits.Contains(item.joints)) << item.id;
    ASSERT_EQ(item.coeffs.size(), 1u);
    const double g = item.coeffs[0];
    EXPECT_GE(g, 0.0);
    EXPECT_LT(g, 1.0);
    // The middle finger's PIP (range 0..max) bends with the grip level.
    const double pip = item.joints[10] / limits.max[10];
    sum_gap += std::abs(pip - g);
    forearms += item.forearm ? 1 : 0;
    EXPECT_EQ(a->at("items").at(item.id).at("forearm").get<bool>(), item.forearm);
  }
  EXPECT_LT(sum_gap / plan->items.size(), 0.15);
  // About half of the photos show the forearm (60 draws of p = 0.5).
  EXPECT_GT(forearms, 15);
  EXPECT_LT(forearms, 45);
  EXPECT_DOUBLE_EQ(plan->photo.forearm_fraction, 0.5);
  EXPECT_FALSE(plan->photo.forearm);

  // Another seed, other poses.
  nlohmann::json other = NaturalConfig();
  other["seed"] = other["seed"].get<uint64_t>() + 1;
  auto c = MakeTestSetPlan(other, DemoConfigPath(), false);
  ASSERT_TRUE(c.ok());
  EXPECT_NE(c->at("items").at(0).at("joints"), a->at("items").at(0).at("joints"));
  // The CLI's --forearm puts the arm on every photo.
  auto all = MakeTestSetPlan(NaturalConfig(), DemoConfigPath(), false, true);
  ASSERT_TRUE(all.ok());
  EXPECT_TRUE(all->at("photo").at("forearm").get<bool>());
  EXPECT_FALSE(all->at("photo").contains("forearm_fraction"));
  EXPECT_FALSE(all->at("items").at(0).contains("forearm"));
}

TEST(TestSetPlan, NaturalPosesRejectFieldsOfTheOtherSource) {
  for (const char* key : {"shapes", "basic_fraction", "basic_names", "pca"}) {
    nlohmann::json config = NaturalConfig();
    config[key] = DemoConfig()[key];
    auto bad = MakeTestSetPlan(config, DemoConfigPath(), false);
    ASSERT_FALSE(bad.ok()) << key;
    EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument) << key;
    EXPECT_NE(bad.status().message().find(key), std::string::npos) << bad.status().message();
  }
  // finger_spread belongs to the natural sampler only.
  nlohmann::json config = DemoConfig();
  config["poses"] = {{"method", "library"}, {"finger_spread", 0.1}};
  auto bad = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("poses.finger_spread"), std::string::npos);
  // The library needs its shapes.
  config = DemoConfig();
  config.erase("shapes");
  bad = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("shapes is required"), std::string::npos);
  // Schema: unknown fields, unknown methods and out-of-range spreads.
  config = NaturalConfig();
  config["poses"]["grip"] = 0.5;
  EXPECT_EQ(MakeTestSetPlan(config, DemoConfigPath(), false).status().code(),
            StatusCode::kSchemaViolation);
  config = NaturalConfig();
  config["poses"]["method"] = "random";
  EXPECT_EQ(MakeTestSetPlan(config, DemoConfigPath(), false).status().code(),
            StatusCode::kSchemaViolation);
  config = NaturalConfig();
  config["poses"]["finger_spread"] = 2;
  EXPECT_EQ(MakeTestSetPlan(config, DemoConfigPath(), false).status().code(),
            StatusCode::kSchemaViolation);
  config = NaturalConfig();
  config["poses"].erase("method");
  EXPECT_EQ(MakeTestSetPlan(config, DemoConfigPath(), false).status().code(),
            StatusCode::kSchemaViolation);
  config = NaturalConfig();
  config["photo"]["forearm_fraction"] = 1.5;
  EXPECT_EQ(MakeTestSetPlan(config, DemoConfigPath(), false).status().code(),
            StatusCode::kSchemaViolation);
  config = NaturalConfig();
  config["photo"]["forearm"] = true;
  bad = MakeTestSetPlan(config, DemoConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("exclude each other"), std::string::npos);
}

TEST(TestSetPlan, ShippedNaturalConfigIsValid) {
  const fs::path path = RepoRoot() / "configs" / "testset-natural.json";
  auto config = ReadJsonFile(path, "testset_config.schema.json");
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  auto doc = MakeTestSetPlan(*config, path, false);
  ASSERT_TRUE(doc.ok()) << doc.status().ToString();
  auto plan = ParseTestSetPlan(*doc, path.string());
  ASSERT_TRUE(plan.ok()) << plan.status().ToString();
  EXPECT_EQ(plan->items.size(), 120u);
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
