#include "pose/fit_kinematics.h"

#include <ceres/ceres.h>
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

#include "base/repo_root.h"
#include "base/testing.h"
#include "generator/hand/hand_model.h"
#include "generator/hand/rig_testing.h"
#include "generator/sampling/random.h"
#include "pose/fit_landmark_cost.h"

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
// dual parts are the full Jets' columns of that digit and the derivatives written out.
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
      double point[3];
      double jacobian[3][kDofs];
      kinematics.KeypointOfDigitWithJacobian(joints.data() + first, k, point, jacobian);
      for (int r = 0; r < 3; ++r) {
        EXPECT_EQ(own[r].a, full[r].a) << "keypoint " << k << " axis " << r;
        EXPECT_EQ(point[r], own[r].a) << "keypoint " << k << " axis " << r;
        for (int i = 0; i < kDofs; ++i) {
          EXPECT_NEAR(jacobian[r][i], own[r].v[i], 1e-12)
              << "keypoint " << k << " axis " << r << " joint " << i;
        }
        for (int i = 0; i < kNumJointAngles; ++i) {
          const bool in_digit = k > 0 && i >= first && i < first + kDofs;
          const double expected = in_digit ? own[r].v[i - first] : 0.0;
          EXPECT_EQ(full[r].v[i], expected) << "keypoint " << k << " axis " << r << " joint " << i;
        }
      }
    }
  }
}

// The fit's landmark cost: LandmarkResidual's values bit for bit and Ceres' automatic derivatives
// of it to rounding, for every keypoint, over poses to the limits and beyond, rotations all round
// (quaternions not quite unit, as a solver's step leaves them before the manifold's), scales and
// shifts; a block the solver holds constant gets no Jacobian and the others are unchanged.
TEST(FitKinematics, LandmarkCostEqualsAutomaticDerivatives) {
  using fit_internal::LandmarkCost;
  using fit_internal::LandmarkResidual;
  constexpr int kDofs = FitKinematics::kDigitDofs;
  const HandRig rig = ShippedRig();
  const FitKinematics kinematics(rig);
  Rng rng(77031);
  int compared = 0;
  for (const JointVector& joints : TestJoints(rig)) {
    std::array<double, 4> q;
    for (double& v : q) v = rng.Uniform() * 2 - 1;
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (double& v : q) v *= (0.98 + 0.04 * rng.Uniform()) / n;
    const double scale = 50 + 150 * rng.Uniform();
    const std::array<double, 2> shift{96 + 20 * rng.Uniform(), 96 - 20 * rng.Uniform()};
    for (int k = 0; k < kNumKeypoints; ++k) {
      const Point2f landmark{static_cast<float>(192 * rng.Uniform()),
                             static_cast<float>(192 * rng.Uniform())};
      const LandmarkResidual residual(&kinematics, k, rig.look_at(), landmark, 0.5);
      const LandmarkCost written(residual);
      std::unique_ptr<ceres::CostFunction> automatic;
      std::vector<const double*> parameters;
      const int first_dof = FitKinematics::DigitOf(k) * kDofs;
      if (k == 0) {
        automatic = std::make_unique<ceres::AutoDiffCostFunction<LandmarkResidual, 2, 4, 1, 2>>(
            new LandmarkResidual(residual));
      } else {
        automatic =
            std::make_unique<ceres::AutoDiffCostFunction<LandmarkResidual, 2, kDofs, 4, 1, 2>>(
                new LandmarkResidual(residual));
        parameters.push_back(joints.data() + first_dof);
      }
      parameters.insert(parameters.end(), {q.data(), &scale, shift.data()});
      ASSERT_EQ(written.parameter_block_sizes(), automatic->parameter_block_sizes());
      const auto& sizes = written.parameter_block_sizes();
      for (size_t held = 0; held <= sizes.size(); ++held) {  // held == size: none held constant
        std::vector<std::vector<double>> want(sizes.size()), got(sizes.size());
        std::vector<double*> want_ptrs, got_ptrs;
        for (size_t b = 0; b < sizes.size(); ++b) {
          want[b].assign(2 * sizes[b], -1.0);
          got[b].assign(2 * sizes[b], -1.0);
          want_ptrs.push_back(b == held ? nullptr : want[b].data());
          got_ptrs.push_back(b == held ? nullptr : got[b].data());
        }
        double want_r[2], got_r[2];
        ASSERT_TRUE(automatic->Evaluate(parameters.data(), want_r, want_ptrs.data()));
        ASSERT_TRUE(written.Evaluate(parameters.data(), got_r, got_ptrs.data()));
        EXPECT_EQ(got_r[0], want_r[0]) << "keypoint " << k;
        EXPECT_EQ(got_r[1], want_r[1]) << "keypoint " << k;
        for (size_t b = 0; b < sizes.size(); ++b) {
          for (size_t i = 0; i < want[b].size(); ++i) {
            EXPECT_NEAR(got[b][i], want[b][i], 1e-12 * (1 + std::abs(want[b][i])))
                << "keypoint " << k << " block " << b << " entry " << i << " held " << held;
          }
        }
        double value_only[2];
        ASSERT_TRUE(written.Evaluate(parameters.data(), value_only, nullptr));
        EXPECT_EQ(value_only[0], want_r[0]);
        EXPECT_EQ(value_only[1], want_r[1]);
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 23 * (4 + 20 * 5));
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
