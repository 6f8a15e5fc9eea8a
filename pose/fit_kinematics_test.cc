#include "pose/fit_kinematics.h"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "base/repo_root.h"
#include "base/testing.h"
#include "generator/hand/hand_model.h"
#include "generator/hand/rig_testing.h"
#include "generator/sampling/random.h"

namespace handdb {
namespace {

using testing::ShippedRig;

// Joint vectors that reach both ends of every limit, zero, and random points between and beyond.
std::vector<JointVector> TestJoints(const HandRig& rig) {
  std::vector<JointVector> out;
  out.push_back(JointVector{});
  out.push_back(rig.limits().min);
  out.push_back(rig.limits().max);
  Rng rng(20240611);
  for (int n = 0; n < 20; ++n) {
    JointVector j;
    for (int i = 0; i < kNumJointAngles; ++i) {
      const double lo = rig.limits().min[i] - 0.3;
      const double hi = rig.limits().max[i] + 0.3;
      j[i] = lo + (hi - lo) * rng.Uniform();
    }
    out.push_back(j);
  }
  return out;
}

TEST(FitKinematics, EqualsHandRigKeypoints) {
  const HandRig rig = ShippedRig();
  const FitKinematics kinematics(rig);
  for (const JointVector& joints : TestJoints(rig)) {
    const HandKeypoints3d expected = rig.Keypoints3d(joints);
    const HandKeypoints3d got = kinematics.Keypoints3d(joints);
    for (int k = 0; k < kNumKeypoints; ++k) {
      for (int r = 0; r < 3; ++r) {
        EXPECT_NEAR(got[k][r], expected[k][r], 1e-9) << "keypoint " << k << " axis " << r;
      }
    }
  }
}

// The derivatives a solver sees: the Jet's dual parts against central differences of the rig.
TEST(FitKinematics, JetDerivativesMatchFiniteDifferences) {
  const HandRig rig = ShippedRig();
  const FitKinematics kinematics(rig);
  using Jet = ceres::Jet<double, kNumJointAngles>;
  const JointVector joints = TestJoints(rig)[5];
  std::array<Jet, kNumJointAngles> jets;
  for (int i = 0; i < kNumJointAngles; ++i) jets[i] = Jet(joints[i], i);
  const double h = 1e-6;
  for (int k = 0; k < kNumKeypoints; ++k) {
    Jet point[3];
    kinematics.Keypoint(jets.data(), k, point);
    for (int i = 0; i < kNumJointAngles; ++i) {
      JointVector plus = joints, minus = joints;
      plus[i] += h;
      minus[i] -= h;
      const HandKeypoints3d a = rig.Keypoints3d(plus);
      const HandKeypoints3d b = rig.Keypoints3d(minus);
      for (int r = 0; r < 3; ++r) {
        EXPECT_NEAR(point[r].v[i], (a[k][r] - b[k][r]) / (2 * h), 1e-7)
            << "keypoint " << k << " axis " << r << " joint " << i;
      }
    }
  }
}

// A digit's keypoints posed from its own 4 angles are the same as from all 20, and their Jets'
// dual parts are the full Jets' columns of that digit.
TEST(FitKinematics, DigitBlocksPoseEachDigitFromItsOwnAngles) {
  const HandRig rig = ShippedRig();
  const FitKinematics kinematics(rig);
  ASSERT_TRUE(kinematics.digit_blocks());
  constexpr int kDofs = FitKinematics::kDigitDofs;
  using Jet = ceres::Jet<double, kNumJointAngles>;
  using DigitJet = ceres::Jet<double, kDofs>;
  for (const JointVector& joints : TestJoints(rig)) {
    std::array<Jet, kNumJointAngles> jets;
    for (int i = 0; i < kNumJointAngles; ++i) jets[i] = Jet(joints[i], i);
    for (int k = 0; k < kNumKeypoints; ++k) {
      const int first = FitKinematics::DigitOf(k) * kDofs;
      std::array<DigitJet, kDofs> digit;
      for (int i = 0; i < kDofs; ++i) digit[i] = DigitJet(joints[first + i], i);
      Jet full[3];
      DigitJet own[3];
      kinematics.Keypoint(jets.data(), k, full);
      kinematics.KeypointOfDigit(digit.data(), k, own);
      for (int r = 0; r < 3; ++r) {
        EXPECT_EQ(own[r].a, full[r].a) << "keypoint " << k << " axis " << r;
        for (int i = 0; i < kNumJointAngles; ++i) {
          const bool in_digit = k > 0 && i >= first && i < first + kDofs;
          const double expected = in_digit ? own[r].v[i - first] : 0.0;
          EXPECT_EQ(full[r].v[i], expected) << "keypoint " << k << " axis " << r << " joint " << i;
        }
      }
    }
  }
}

// A rig whose DOF turns a bone of another digit cannot be posed per digit, and says so.
TEST(FitKinematics, DofOnAnotherDigitBreaksDigitBlocks) {
  auto model = LoadHandModel(RepoRoot() / "configs/hands/webxr_generic_right.json");
  ASSERT_TRUE(model.ok());
  // The index finger's MCP flexion (DOF 4) moved onto the thumb's first bone.
  model->dofs[4].bone = model->dofs[0].bone;
  auto rig = HandRig::Create(*model);
  ASSERT_TRUE(rig.ok()) << rig.status().message();
  EXPECT_FALSE(FitKinematics(*rig).digit_blocks());
}

}  // namespace
}  // namespace handdb
