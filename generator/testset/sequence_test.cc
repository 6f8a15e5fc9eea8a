#include "generator/testset/sequence.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "base/json_schema.h"
#include "generator/hand/camera.h"
#include "generator/hand/hand_model.h"
#include "generator/testset/testset.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

fs::path SequenceConfigPath() { return RepoRoot() / "configs" / "testset-sequence.json"; }

nlohmann::json SequenceConfig() {
  auto doc = ReadJsonFile(SequenceConfigPath(), "testset_config.schema.json");
  THROW_CHECK_MSG(doc.ok(), doc.status().ToString());
  return *doc;
}

JointLimits Limits() {
  auto hand = LoadHandModel(RepoRoot() / "configs/hands/webxr_generic_right.json");
  THROW_CHECK_MSG(hand.ok(), hand.status().ToString());
  return hand->limits();
}

double AngleDeg(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  return std::acos(std::clamp(dot, -1.0, 1.0)) * 180.0 / M_PI;
}

TEST(SequencePlan, ShippedConfigIsDeterministicAndValid) {
  auto a = MakeTestSetPlan(SequenceConfig(), SequenceConfigPath(), false);
  auto b = MakeTestSetPlan(SequenceConfig(), SequenceConfigPath(), false);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(a->dump(), b->dump());
  auto plan = ParseTestSetPlan(*a, "sequence");
  ASSERT_TRUE(plan.ok()) << plan.status().ToString();
  ASSERT_EQ(plan->items.size(), 240u);
  EXPECT_EQ(plan->unit_size, 60u);  // one unit per sequence by default
  EXPECT_EQ(plan->num_units(), 4u);
  EXPECT_EQ(a->at("sequence").at("frames").get<int>(), 60);
  for (const TestSetItem& item : plan->items) {
    ASSERT_TRUE(item.sequence.has_value()) << item.id;
    EXPECT_EQ(item.sequence->sequence, item.id / 60);
    EXPECT_EQ(item.sequence->frame, item.id % 60);
    EXPECT_DOUBLE_EQ(item.sequence->time, (item.id % 60) / 30.0);
    // Alternating backgrounds.
    EXPECT_EQ(item.clutter, item.sequence->sequence % 2 == 1) << item.id;
  }
  // Another seed, other sequences.
  nlohmann::json other = SequenceConfig();
  other["seed"] = other["seed"].get<uint64_t>() + 1;
  auto c = MakeTestSetPlan(other, SequenceConfigPath(), false);
  ASSERT_TRUE(c.ok());
  EXPECT_NE(c->at("items").at(0).at("joints"), a->at("items").at(0).at("joints"));
  EXPECT_NE(c->at("items").at(0).at("direction"), a->at("items").at(0).at("direction"));
}

TEST(SequencePlan, FramesAreSmoothAndWithinLimits) {
  auto doc = MakeTestSetPlan(SequenceConfig(), SequenceConfigPath(), false);
  ASSERT_TRUE(doc.ok()) << doc.status().ToString();
  auto plan = ParseTestSetPlan(*doc, "sequence");
  ASSERT_TRUE(plan.ok());
  const JointLimits limits = Limits();
  double max_joint_step = 0;
  double max_turn = 0;
  double max_roll_step = 0;
  double keypose_change = 0;
  for (size_t i = 0; i < plan->items.size(); ++i) {
    const TestSetItem& item = plan->items[i];
    EXPECT_TRUE(limits.Contains(item.joints)) << i;
    if (item.sequence->frame == 0) continue;
    const TestSetItem& prev = plan->items[i - 1];
    for (int k = 0; k < kNumJointAngles; ++k) {
      max_joint_step = std::max(max_joint_step, std::abs(item.joints[k] - prev.joints[k]));
    }
    max_turn = std::max(max_turn, AngleDeg(item.direction, prev.direction));
    // The camera's whole rotation between frames: the turn and the roll, never a spin.
    auto a = CamFromHandRotation(item.direction, plan->forward_axis, plan->palm_normal, item.roll);
    auto b = CamFromHandRotation(prev.direction, plan->forward_axis, plan->palm_normal, prev.roll);
    ASSERT_TRUE(a.ok() && b.ok());
    double trace = 0;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) trace += (*a)[r][c] * (*b)[r][c];
    }
    max_roll_step =
        std::max(max_roll_step, std::acos(std::clamp((trace - 1) / 2, -1.0, 1.0)) * 180 / M_PI);
    if (item.sequence->frame == 59) {
      const TestSetItem& first = plan->items[i - 59];
      for (int k = 0; k < kNumJointAngles; ++k) {
        keypose_change = std::max(keypose_change, std::abs(item.joints[k] - first.joints[k]));
      }
    }
  }
  // Smoothstep between keyposes 20 frames apart: at most 1.5 / 20 of a joint's range per frame.
  double max_range = 0;
  for (int k = 0; k < kNumJointAngles; ++k) {
    max_range = std::max(max_range, limits.max[k] - limits.min[k]);
  }
  EXPECT_LE(max_joint_step, 1.5 / 20 * max_range + 1e-9);
  EXPECT_GT(keypose_change, 0.1);  // the hand does move between keyposes
  EXPECT_NEAR(max_turn, 1.0, 1e-6);
  // 1 deg of turn and 0.5 deg of roll per frame: at most 1.5 deg together.
  EXPECT_LE(max_roll_step, 1.5);
  EXPECT_GE(max_roll_step, 1.0);
}

TEST(SequencePlan, LeaveStretchesAreMarkedAndReturn) {
  auto doc = MakeTestSetPlan(SequenceConfig(), SequenceConfigPath(), false);
  ASSERT_TRUE(doc.ok());
  auto plan = ParseTestSetPlan(*doc, "sequence");
  ASSERT_TRUE(plan.ok());
  std::set<uint32_t> leaving_sequences;
  for (const TestSetItem& item : plan->items) {
    const double shift = std::hypot(item.photo_offset_px[0], item.photo_offset_px[1]);
    EXPECT_EQ(item.sequence->leaving, shift > 0) << item.id;
    if (!item.sequence->leaving) continue;
    leaving_sequences.insert(item.sequence->sequence);
    // From frame 24 (0.4 x 60): 6 frames out, 8 at the full shift, 6 back in.
    EXPECT_GT(item.sequence->frame, 24u);
    EXPECT_LT(item.sequence->frame, 24u + 6 + 8 + 6);
    const uint32_t i = item.sequence->frame - 24;
    if (i >= 6 && i < 14) {
      EXPECT_NEAR(shift, 1.25 * 256, 1e-9) << item.id;
    }
  }
  EXPECT_EQ(leaving_sequences, (std::set<uint32_t>{2, 3}));
  // The shift grows and shrinks smoothly: the last frame of the stretch is back at 0.
  const TestSetItem& back = plan->items[2 * 60 + 24 + 20];
  EXPECT_FALSE(back.sequence->leaving);
}

TEST(SequencePlan, RejectsInconsistentConfigs) {
  nlohmann::json config = SequenceConfig();
  config["count"] = 100;
  auto bad = MakeTestSetPlan(config, SequenceConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("sequence.sequences x sequence.frames"), std::string::npos)
      << bad.status().message();

  config = SequenceConfig();
  config["sequence"]["leave"]["sequences"] = {4};
  bad = MakeTestSetPlan(config, SequenceConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("names sequence 4 of 4"), std::string::npos);

  config = SequenceConfig();
  config["sequence"]["leave"]["start"] = 0.9;
  bad = MakeTestSetPlan(config, SequenceConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("must end before the last"), std::string::npos);

  config = SequenceConfig();
  config["poses"]["method"] = "library";
  bad = MakeTestSetPlan(config, SequenceConfigPath(), false);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("natural"), std::string::npos);
}

TEST(SequenceOptions, Check) {
  SequenceOptions o;
  EXPECT_TRUE(o.Check());
  o.leave.sequences = {9};
  EXPECT_FALSE(o.Check());
  o = SequenceOptions();
  o.fps = 0;
  EXPECT_FALSE(o.Check());
}

TEST(SequenceOptions, JsonRoundTrip) {
  auto o = SequenceOptions::FromJson(SequenceConfig().at("sequence"), "cfg");
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  auto back = SequenceOptions::FromJson(o->ToJson(), "cfg");
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->ToJson(), o->ToJson());
  EXPECT_EQ(o->leave.sequences, (std::vector<uint32_t>{2, 3}));
}

TEST(TestSetPlan, SequenceFramePath) {
  EXPECT_EQ(SequenceFramePath("/d", 2, 17), fs::path("/d/sequences/s002/000017.png"));
}

}  // namespace
}  // namespace handdb
