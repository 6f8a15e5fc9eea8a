#include "pose/fit_kinematics.h"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "base/testing.h"
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

}  // namespace
}  // namespace handdb
