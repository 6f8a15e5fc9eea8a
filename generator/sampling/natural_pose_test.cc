#include "generator/sampling/natural_pose.h"

#include <gtest/gtest.h>

#include <cmath>

#include "base/repo_root.h"
#include "generator/hand/hand_model.h"

namespace handdb {
namespace {

JointLimits ShippedLimits() {
  auto model = LoadHandModel(RepoRoot() / "configs/hands/webxr_generic_right.json");
  THROW_CHECK(model.ok());
  return model->limits();
}

// The mean over the four fingers' flexion DOFs of (value - rest) / (max - rest): 0 flat, 1 fist.
double MeanFingerFlexion(const JointVector& joints, const JointLimits& limits) {
  double sum = 0;
  int n = 0;
  for (int f = 1; f < kNumFingers; ++f) {
    for (int k : FingerFlexionDofs(f)) {
      const double rest = std::clamp(0.0, limits.min[k], limits.max[k]);
      sum += (joints[k] - rest) / (limits.max[k] - rest);
      ++n;
    }
  }
  return sum / n;
}

TEST(NaturalPose, OptionsCheck) {
  EXPECT_TRUE(NaturalPoseOptions().Check());
  NaturalPoseOptions bad;
  bad.finger_spread = -0.1;
  EXPECT_FALSE(bad.Check());
  bad = NaturalPoseOptions();
  bad.abduction_spread = 1.5;
  EXPECT_FALSE(bad.Check());
}

TEST(NaturalPose, DofsFollowTheConventions) {
  EXPECT_EQ(FingerFlexionDofs(0), (std::array<int, 3>{0, 2, 3}));  // thumb CMC, MCP, IP
  EXPECT_EQ(FingerAbductionDof(0), 1);
  EXPECT_EQ(FingerFlexionDofs(2), (std::array<int, 3>{8, 10, 11}));  // middle MCP, PIP, DIP
  EXPECT_EQ(FingerAbductionDof(4), 17);                              // pinky MCP abduction
}

TEST(NaturalPose, DeterministicPerIndexAndSeed) {
  const JointLimits limits = ShippedLimits();
  NaturalPoseOptions options;
  options.seed = 42;
  const NaturalPose a = SampleNaturalPose(options, limits, 7);
  const NaturalPose b = SampleNaturalPose(options, limits, 7);
  EXPECT_EQ(a.joints, b.joints);
  EXPECT_EQ(a.grip, b.grip);
  EXPECT_NE(SampleNaturalPose(options, limits, 8).joints, a.joints);
  options.seed = 43;
  EXPECT_NE(SampleNaturalPose(options, limits, 7).joints, a.joints);
}

TEST(NaturalPose, WithinTheJointLimits) {
  const JointLimits limits = ShippedLimits();
  NaturalPoseOptions options;
  options.seed = 3;
  options.finger_spread = 0.5;  // wide, so that clamping happens
  options.abduction_spread = 1.0;
  int clamped = 0;
  for (uint64_t i = 0; i < 500; ++i) {
    const NaturalPose p = SampleNaturalPose(options, limits, i);
    EXPECT_TRUE(limits.Contains(p.joints)) << i;
    clamped += p.clamped ? 1 : 0;
  }
  EXPECT_GT(clamped, 0);
}

TEST(NaturalPose, FingerFlexionTracksTheGripLevel) {
  const JointLimits limits = ShippedLimits();
  NaturalPoseOptions options;
  options.seed = 11;
  const int n = 2000;
  double sg = 0, sf = 0, sgg = 0, sff = 0, sgf = 0, max_gap = 0, min_g = 1, max_g = 0;
  for (int i = 0; i < n; ++i) {
    const NaturalPose p = SampleNaturalPose(options, limits, i);
    const double f = MeanFingerFlexion(p.joints, limits);
    sg += p.grip;
    sf += f;
    sgg += p.grip * p.grip;
    sff += f * f;
    sgf += p.grip * f;
    max_gap = std::max(max_gap, std::abs(f - p.grip));
    min_g = std::min(min_g, p.grip);
    max_g = std::max(max_g, p.grip);
  }
  const double cov = sgf / n - (sg / n) * (sf / n);
  const double corr =
      cov / std::sqrt((sgg / n - (sg / n) * (sg / n)) * (sff / n - (sf / n) * (sf / n)));
  EXPECT_GT(corr, 0.95);
  // Four fingers' own levels (std 0.15) average to std 0.075 around g; clamping only pulls in.
  EXPECT_LT(max_gap, 0.4);
  EXPECT_NEAR(sg / n, 0.5, 0.03);  // g ~ U[0, 1]
  EXPECT_LT(min_g, 0.01);
  EXPECT_GT(max_g, 0.99);
}

TEST(NaturalPose, ZeroSpreadIsTheGripExactly) {
  const JointLimits limits = ShippedLimits();
  NaturalPoseOptions options;
  options.finger_spread = 0;
  options.abduction_spread = 0;
  const NaturalPose p = SampleNaturalPose(options, limits, 5);
  for (int f = 0; f < kNumFingers; ++f) {
    for (int k : FingerFlexionDofs(f)) {
      const double rest = std::clamp(0.0, limits.min[k], limits.max[k]);
      EXPECT_NEAR(p.joints[k], rest + p.grip * (limits.max[k] - rest), 1e-12);
    }
    EXPECT_EQ(p.joints[FingerAbductionDof(f)], 0.0);
  }
  EXPECT_FALSE(p.clamped);
}

}  // namespace
}  // namespace handdb
