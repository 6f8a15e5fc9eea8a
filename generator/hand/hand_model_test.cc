#include "generator/hand/hand_model.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/sha256.h"
#include "base/testing.h"

namespace handdb {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

fs::path HandPath() { return RepoRoot() / "configs/hands/webxr_generic_right.json"; }
fs::path ShapesPath() { return RepoRoot() / "configs/shapes/basic.json"; }

TEST(HandModel, LoadsTheShippedModel) {
  auto model = LoadHandModel(HandPath());
  ASSERT_TRUE(model.ok()) << model.status().message();
  ASSERT_EQ(model->dofs.size(), 20u);
  EXPECT_EQ(model->dofs[0].name, "thumb_cmc_flexion");  // docs/conventions.md DOF order
  EXPECT_EQ(model->dofs[19].name, "pinky_dip_flexion");
  ASSERT_EQ(model->links.size(), 16u);
  EXPECT_EQ(model->links[0].name, "palm");
  EXPECT_EQ(model->joint_pairs.size(), 15u);
  EXPECT_TRUE(model->IsJointPair(1, 5));
  EXPECT_TRUE(model->IsJointPair(6, 5));
  EXPECT_FALSE(model->IsJointPair(5, 8));
  EXPECT_EQ(model->keypoint_names.size(), 21u);
  EXPECT_GT(model->ortho_scale, 0);
  auto digest = Sha256File(HandPath());
  ASSERT_TRUE(digest.ok());
  EXPECT_EQ(model->sha256, *digest);
  const JointLimits limits = model->limits();
  for (int i = 0; i < kNumJointAngles; ++i) EXPECT_LT(limits.min[i], limits.max[i]) << i;
}

TEST(HandModel, ShippedShapesAreWithinLimits) {
  auto model = LoadHandModel(HandPath());
  ASSERT_TRUE(model.ok());
  auto shapes = LoadShapes(ShapesPath(), model->limits());
  ASSERT_TRUE(shapes.ok()) << shapes.status().message();
  EXPECT_GE(shapes->size(), 26u);
  for (const auto& s : *shapes) EXPECT_TRUE(model->limits().Contains(s.joints)) << s.name;
}

TEST(HandModel, ClampReportsChanges) {
  JointLimits limits;
  limits.min.fill(-1);
  limits.max.fill(1);
  JointVector j{};
  EXPECT_FALSE(limits.Clamp(&j));
  j[3] = 2;
  j[7] = -5;
  EXPECT_TRUE(limits.Clamp(&j));
  EXPECT_EQ(j[3], 1);
  EXPECT_EQ(j[7], -1);
  EXPECT_TRUE(limits.Contains(j));
}

TEST(HandModel, RejectsBrokenFiles) {
  auto dir = handdb::testing::TempDir("hand_broken");
  auto text = ReadFileToString(HandPath());
  ASSERT_TRUE(text.ok());
  const json good = json::parse(*text);

  json swapped = good;
  std::swap(swapped["dofs"][0]["min"], swapped["dofs"][0]["max"]);
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "swapped.json", swapped).ok());
  auto r = LoadHandModel(dir / "swapped.json");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("swapped.json"), std::string::npos) << r.status().message();

  json short_dofs = good;
  short_dofs["dofs"].erase(short_dofs["dofs"].begin() + 5);
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "short.json", short_dofs).ok());
  r = LoadHandModel(dir / "short.json");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kSchemaViolation);

  ASSERT_TRUE(WriteFileAtomic(dir / "garbage.json", "{\"dofs\": [").ok());
  r = LoadHandModel(dir / "garbage.json");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kBadJson);

  r = LoadHandModel(dir / "missing.json");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
}

TEST(HandModel, RejectsShapesOutsideTheLimits) {
  auto dir = handdb::testing::TempDir("hand_shapes");
  auto model = LoadHandModel(HandPath());
  ASSERT_TRUE(model.ok());
  auto text = ReadFileToString(ShapesPath());
  ASSERT_TRUE(text.ok());
  json doc = json::parse(*text);
  doc["shapes"][2]["joints"][4] = 3.0;  // index MCP flexion far past its limit
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "bad.json", doc).ok());
  auto r = LoadShapes(dir / "bad.json", model->limits());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kOutOfRange);
  EXPECT_NE(r.status().message().find("joint 4"), std::string::npos) << r.status().message();

  doc = json::parse(*text);
  doc["shapes"][1]["name"] = doc["shapes"][0]["name"];
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "dup.json", doc).ok());
  r = LoadShapes(dir / "dup.json", model->limits());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("duplicate"), std::string::npos) << r.status().message();
}

}  // namespace
}  // namespace handdb
