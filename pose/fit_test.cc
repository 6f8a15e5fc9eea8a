#include "pose/fit.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "base/repo_root.h"
#include "generator/hand/hand_model.h"
#include "generator/hand/rig_testing.h"
#include "pose/fit_kinematics.h"

namespace handdb {
namespace {

using testing::ShippedRig;

// A pose of the test: joints, camera, and the normalised frame's scale and shift.
struct Pose {
  JointVector joints{};
  Mat3d cam_from_hand{};
  double scale = 0;
  std::array<double, 2> shift{};
};

NormalisedKeypoints2d Project(const HandRig& rig, const Pose& pose) {
  const HandKeypoints3d points = rig.Keypoints3d(pose.joints);
  NormalisedKeypoints2d out;
  for (int k = 0; k < kNumKeypoints; ++k) {
    double xy[2];
    for (int r = 0; r < 2; ++r) {
      xy[r] = 0;
      for (int c = 0; c < 3; ++c) {
        xy[r] += pose.cam_from_hand[r][c] * (points[k][c] - rig.look_at()[c]);
      }
      xy[r] = pose.scale * xy[r] + pose.shift[r];
    }
    out[k] = {static_cast<float>(xy[0]), static_cast<float>(xy[1])};
  }
  return out;
}

// Root-relative 3D keypoints in the camera frame, in wrist-to-middle-knuckle lengths of `truth`.
double Error3d(const HandRig& rig,
               const JointVector& joints,
               const Mat3d& cam_from_hand,
               const Pose& truth) {
  const auto in_cam = [](const HandKeypoints3d& points, const Mat3d& rotation) {
    HandKeypoints3d out;
    for (int k = 0; k < kNumKeypoints; ++k) {
      for (int r = 0; r < 3; ++r) {
        out[k][r] = 0;
        for (int c = 0; c < 3; ++c) out[k][r] += rotation[r][c] * (points[k][c] - points[0][c]);
      }
    }
    return out;
  };
  const HandKeypoints3d a = in_cam(rig.Keypoints3d(joints), cam_from_hand);
  const HandKeypoints3d b = in_cam(rig.Keypoints3d(truth.joints), truth.cam_from_hand);
  const double unit = std::hypot(b[9][0], b[9][1], b[9][2]);
  double sum = 0;
  for (int k = 1; k < kNumKeypoints; ++k) {
    sum += std::hypot(a[k][0] - b[k][0], a[k][1] - b[k][1], a[k][2] - b[k][2]);
  }
  return sum / (kNumKeypoints - 1) / unit;
}

Mat3d Multiply(const Mat3d& a, const Mat3d& b) {
  Mat3d out{};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      for (int i = 0; i < 3; ++i) out[r][c] += a[r][i] * b[i][c];
    }
  }
  return out;
}

Mat3d Rotation(Vec3d axis, double angle) {
  const double n = std::hypot(axis[0], axis[1], axis[2]);
  const double unit[3] = {axis[0] / n, axis[1] / n, axis[2] / n};
  double r[3][3];
  fit_internal::AxisAngleRotation(unit, angle, r);
  Mat3d out;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) out[i][j] = r[i][j];
  }
  return out;
}

// A natural pose: every joint inside its limits, away from both ends, seen obliquely.
Pose TruePose(const HandRig& rig) {
  Pose pose;
  for (int i = 0; i < kNumJointAngles; ++i) {
    const double f = 0.3 + 0.4 * std::fmod(0.37 * i, 1.0);
    pose.joints[i] = rig.limits().min[i] + (rig.limits().max[i] - rig.limits().min[i]) * f;
  }
  auto cam = CamFromHand(rig, {0.4, -0.3, 0.87}, 0.3);
  THROW_CHECK(cam.ok());
  pose.cam_from_hand = *cam;
  pose.scale = 900;
  pose.shift = {3, -5};
  return pose;
}

// The candidate the search would return: joints +-0.2 rad, the camera turned by 10 degrees, the
// scale 5% off and the shift a few px off.
Pose PerturbedPose(const HandRig& rig, const Pose& truth) {
  Pose pose = truth;
  for (int i = 0; i < kNumJointAngles; ++i) pose.joints[i] += (i % 2 == 0 ? 0.2 : -0.2);
  rig.limits().Clamp(&pose.joints);
  pose.cam_from_hand =
      Multiply(truth.cam_from_hand, Rotation({1, 2, 3}, 10 * std::acos(-1.0) / 180));
  pose.scale = truth.scale * 1.05;
  pose.shift = {truth.shift[0] + 4, truth.shift[1] - 3};
  return pose;
}

PoseFitStart StartAt(const HandRig& rig, const Pose& pose) {
  PoseFitStart start;
  start.joints = pose.joints;
  THROW_CHECK(ViewOfCamFromHand(rig, pose.cam_from_hand, &start.view_direction, &start.roll).ok());
  start.keypoints_normalised = Project(rig, pose);
  return start;
}

PoseFitEvidence EvidenceOf(const NormalisedKeypoints2d& landmarks) {
  PoseFitEvidence evidence;
  evidence.has_landmarks = true;
  evidence.landmarks_px = landmarks;
  return evidence;
}

double MaxDistance(const NormalisedKeypoints2d& a, const NormalisedKeypoints2d& b) {
  double worst = 0;
  for (int k = 0; k < kNumKeypoints; ++k) {
    worst = std::max(worst, static_cast<double>(std::hypot(a[k].x - b[k].x, a[k].y - b[k].y)));
  }
  return worst;
}

TEST(PoseFitOptions, Check) {
  EXPECT_TRUE(PoseFitOptions().Check());
  PoseFitOptions bad;
  bad.max_iterations = 0;
  EXPECT_FALSE(bad.Check());
  bad = PoseFitOptions();
  bad.landmark_sigma_px = std::nan("");
  EXPECT_FALSE(bad.Check());
  bad = PoseFitOptions();
  bad.joint_prior_sigma = 0;
  EXPECT_FALSE(bad.Check());
  bad = PoseFitOptions();
  bad.depth_sigma = 0;
  EXPECT_FALSE(bad.Check());
  bad = PoseFitOptions();
  bad.depth_weight = -1;
  EXPECT_FALSE(bad.Check());
}

TEST(ViewOfCamFromHand, InvertsCamFromHand) {
  const HandRig rig = ShippedRig();
  for (const double roll : {0.0, 0.7, -2.5}) {
    for (const Vec3d& d : {Vec3d{0.4, -0.3, 0.87}, Vec3d{0, 0, 1}, Vec3d{-0.6, 0.1, -0.2}}) {
      auto cam = CamFromHand(rig, d, roll);
      ASSERT_TRUE(cam.ok());
      Vec3d direction;
      double got_roll = 0;
      ASSERT_TRUE(ViewOfCamFromHand(rig, *cam, &direction, &got_roll).ok());
      auto again = CamFromHand(rig, direction, got_roll);
      ASSERT_TRUE(again.ok());
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) EXPECT_NEAR((*again)[r][c], (*cam)[r][c], 1e-12);
      }
      EXPECT_NEAR(got_roll, roll, 1e-12);
    }
  }
}

// The start of a stored view (v, r) reproduces its normalised keypoints exactly: the fit's model
// (scale, shift, rotation with the roll inside) is the renders' camera and the normalisation.
TEST(PoseFit, StartFromLabelAlignsWithItsKeypoints) {
  const HandRig rig = ShippedRig();
  const Pose truth = TruePose(rig);
  ViewLabel label;
  for (int i = 0; i < kNumJointAngles; ++i) {
    label.joint_angles[i] = static_cast<float>(truth.joints[i]);
  }
  label.view_direction = {0.4f, -0.3f, 0.87f};
  label.camera_roll = 0.3f;
  label.scale = 1.5f;
  label.source_centre_px = {130.25f, 140.75f};
  auto start = PoseFitStartFromLabel(rig, label, RenderSettings{256, 0.3}, 0.9);
  ASSERT_TRUE(start.ok()) << start.status().message();
  PoseFitEvidence none;
  auto fit = FitPose(rig, *start, none, PoseFitOptions());
  ASSERT_TRUE(fit.ok()) << fit.status().message();
  EXPECT_LT(fit->start_alignment_rms_px, 1e-3);
  EXPECT_LT(MaxDistance(fit->keypoints_normalised, start->keypoints_normalised), 1e-3);
}

TEST(PoseFit, RecoversAPerturbedSyntheticView) {
  const HandRig rig = ShippedRig();
  const Pose truth = TruePose(rig);
  const Pose perturbed = PerturbedPose(rig, truth);
  const NormalisedKeypoints2d landmarks = Project(rig, truth);
  const PoseFitStart start = StartAt(rig, perturbed);

  auto fit = FitPose(rig, start, EvidenceOf(landmarks), PoseFitOptions());
  ASSERT_TRUE(fit.ok()) << fit.status().message();
  EXPECT_TRUE(fit->converged) << fit->termination << ": " << fit->message;
  EXPECT_LE(fit->iterations, PoseFitOptions().max_iterations + 1);
  EXPECT_LT(fit->final_cost, fit->initial_cost);
  EXPECT_NEAR(fit->final_cost, fit->landmark_cost + fit->prior_cost, 1e-9 * fit->initial_cost);

  const double start_2d = MaxDistance(Project(rig, perturbed), landmarks);
  const double fitted_2d = MaxDistance(fit->keypoints_normalised, landmarks);
  EXPECT_GT(start_2d, 10);
  EXPECT_LT(fitted_2d, 0.5);

  const double start_3d = Error3d(rig, perturbed.joints, perturbed.cam_from_hand, truth);
  const double fitted_3d = Error3d(rig, fit->joints, fit->cam_from_hand, truth);
  EXPECT_LT(fitted_3d, start_3d / 4) << "start " << start_3d << ", fitted " << fitted_3d;
  EXPECT_NEAR(fit->scale, truth.scale, 0.02 * truth.scale);
  EXPECT_TRUE(rig.OutsideLimits(fit->joints).empty());
}

TEST(PoseFit, JointsStayWithinLimits) {
  const HandRig rig = ShippedRig();
  // The start has the index MCP and every PIP curled almost to its limit; the evidence is the
  // same hand curled past it.
  const std::array<int, 5> pulled = {4, 6, 10, 14, 18};
  Pose near_limit = TruePose(rig);
  Pose beyond = near_limit;
  for (const int i : pulled) {
    near_limit.joints[i] = rig.limits().max[i] - 0.1;
    beyond.joints[i] = rig.limits().max[i] + 0.3;
  }
  const PoseFitStart start = StartAt(rig, near_limit);

  PoseFitOptions options;
  options.joint_prior_sigma = 10;  // let the evidence pull as hard as it can
  auto fit = FitPose(rig, start, EvidenceOf(Project(rig, beyond)), options);
  ASSERT_TRUE(fit.ok()) << fit.status().message();
  EXPECT_TRUE(rig.OutsideLimits(fit->joints, 0).empty());
  for (const int i : pulled) {
    EXPECT_NEAR(fit->joints[i], rig.limits().max[i], 0.02) << "joint " << i;
  }
}

TEST(PoseFit, NonFiniteEvidenceIsAnError) {
  const HandRig rig = ShippedRig();
  const Pose truth = TruePose(rig);
  const PoseFitStart start = StartAt(rig, truth);
  PoseFitEvidence evidence = EvidenceOf(Project(rig, truth));
  evidence.landmarks_px[7].y = std::nanf("");
  auto fit = FitPose(rig, start, evidence, PoseFitOptions());
  ASSERT_FALSE(fit.ok());
  EXPECT_EQ(fit.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(fit.status().message().find("landmark 7"), std::string::npos) << fit.status().message();

  evidence = EvidenceOf(Project(rig, truth));
  evidence.weights[3] = -1;
  EXPECT_EQ(FitPose(rig, start, evidence, PoseFitOptions()).status().code(),
            StatusCode::kInvalidArgument);

  PoseFitStart bad_start = start;
  bad_start.keypoints_normalised[0].x = INFINITY;
  EXPECT_EQ(
      FitPose(rig, bad_start, EvidenceOf(Project(rig, truth)), PoseFitOptions()).status().code(),
      StatusCode::kInvalidArgument);

  PoseFitOptions bad_options;
  bad_options.max_iterations = 0;
  EXPECT_EQ(FitPose(rig, start, EvidenceOf(Project(rig, truth)), bad_options).status().code(),
            StatusCode::kInvalidArgument);
}

// The fit differentiates each digit's keypoints with respect to its own angles only: a rig whose
// DOFs are not grouped by digit as docs/conventions.md orders them is refused with the reason.
TEST(PoseFit, RigWithoutDigitBlocksIsAnError) {
  auto model = LoadHandModel(RepoRoot() / "configs/hands/webxr_generic_right.json");
  ASSERT_TRUE(model.ok());
  model->dofs[4].bone = model->dofs[0].bone;  // the index MCP flexion on the thumb
  auto moved = HandRig::Create(*model);
  ASSERT_TRUE(moved.ok()) << moved.status().message();
  const HandRig rig = ShippedRig();
  const Pose truth = TruePose(rig);
  auto fit =
      FitPose(*moved, StartAt(rig, truth), EvidenceOf(Project(rig, truth)), PoseFitOptions());
  ASSERT_FALSE(fit.ok());
  EXPECT_EQ(fit.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(fit.status().message().find("DOFs"), std::string::npos) << fit.status().message();
}

TEST(PoseFit, WithoutLandmarksThePriorKeepsTheStart) {
  const HandRig rig = ShippedRig();
  const Pose perturbed = PerturbedPose(rig, TruePose(rig));
  const PoseFitStart start = StartAt(rig, perturbed);
  for (const bool has_landmarks : {false, true}) {
    // Landmarks that are present but all weighted 0 count as none, whatever they hold.
    PoseFitEvidence evidence;
    evidence.has_landmarks = has_landmarks;
    evidence.weights.fill(0.0f);
    auto fit = FitPose(rig, start, evidence, PoseFitOptions());
    ASSERT_TRUE(fit.ok()) << fit.status().message();
    EXPECT_TRUE(fit->converged) << fit->termination << ": " << fit->message;
    for (int i = 0; i < kNumJointAngles; ++i) EXPECT_NEAR(fit->joints[i], start.joints[i], 1e-12);
    EXPECT_NEAR(fit->roll, start.roll, 1e-9);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(fit->view_direction[i], start.view_direction[i], 1e-9);
    EXPECT_NEAR(fit->scale, perturbed.scale, 1e-6 * perturbed.scale);
    EXPECT_LT(MaxDistance(fit->keypoints_normalised, start.keypoints_normalised), 1e-3);
    EXPECT_EQ(fit->landmark_cost, 0);
  }
}

// The truth's depths as the fit's depth evidence: each keypoint's camera z in the rig's
// wrist-to-middle-knuckle lengths.
std::array<float, kNumKeypoints> DepthsOf(const HandRig& rig, const Pose& pose) {
  const HandKeypoints3d p = rig.Keypoints3d(pose.joints);
  const double length = std::hypot(p[9][0] - p[0][0], p[9][1] - p[0][1], p[9][2] - p[0][2]);
  std::array<float, kNumKeypoints> out{};
  for (int k = 0; k < kNumKeypoints; ++k) {
    double z = 0;
    for (int c = 0; c < 3; ++c) z += pose.cam_from_hand[2][c] * p[k][c];
    out[k] = static_cast<float>(z / length);
  }
  return out;
}

// A rotation as a unit quaternion (w, x, y, z), from its largest component (Shepperd).
std::array<double, 4> QuaternionOfRotation(const Mat3d& m) {
  const double t[4] = {m[0][0] + m[1][1] + m[2][2],
                       m[0][0] - m[1][1] - m[2][2],
                       -m[0][0] + m[1][1] - m[2][2],
                       -m[0][0] - m[1][1] + m[2][2]};
  const int i = static_cast<int>(std::max_element(t, t + 4) - t);
  const double s = 0.5 / std::sqrt(1 + t[i]);
  switch (i) {
    case 0:
      return {0.25 / s, (m[2][1] - m[1][2]) * s, (m[0][2] - m[2][0]) * s, (m[1][0] - m[0][1]) * s};
    case 1:
      return {(m[2][1] - m[1][2]) * s, 0.25 / s, (m[0][1] + m[1][0]) * s, (m[0][2] + m[2][0]) * s};
    case 2:
      return {(m[0][2] - m[2][0]) * s, (m[0][1] + m[1][0]) * s, 0.25 / s, (m[1][2] + m[2][1]) * s};
    default:
      return {(m[1][0] - m[0][1]) * s, (m[0][2] + m[2][0]) * s, (m[1][2] + m[2][1]) * s, 0.25 / s};
  }
}

TEST(PoseFit, DepthGradientMatchesNumericDifferences) {
  const HandRig rig = ShippedRig();
  const Pose truth = TruePose(rig);
  const Pose at = PerturbedPose(rig, truth);
  PoseFitEvidence evidence = EvidenceOf(Project(rig, truth));
  evidence.has_depths = true;
  evidence.depths = DepthsOf(rig, truth);
  for (int k = 0; k < kNumKeypoints; ++k) evidence.weights[k] = 0.5f + 0.02f * k;
  const std::array<double, 4> q = QuaternionOfRotation(at.cam_from_hand);
  for (const bool from_wrist : {false, true}) {
    PoseFitOptions options;
    options.depth_weight = 2;
    options.depth_from_wrist = from_wrist;
    std::vector<double> gradient;
    const double cost = DepthTermCost(rig, evidence, options, at.joints, q, &gradient);
    ASSERT_EQ(gradient.size(), static_cast<size_t>(kNumJointAngles + 4));
    EXPECT_GT(cost, 0);
    const auto cost_at = [&](int i, double h) {
      JointVector j = at.joints;
      std::array<double, 4> qq = q;
      if (i < kNumJointAngles) {
        j[i] += h;
      } else {
        qq[i - kNumJointAngles] += h;
      }
      return DepthTermCost(rig, evidence, options, j, qq);
    };
    int checked = 0;
    for (int i = 0; i < static_cast<int>(gradient.size()); ++i) {
      const double h = 1e-6;
      const double numeric = (cost_at(i, h) - cost_at(i, -h)) / (2 * h);
      EXPECT_NEAR(gradient[i], numeric, 1e-5 * std::abs(numeric) + 1e-6 * (1 + cost))
          << "parameter " << i << (from_wrist ? ", from the wrist" : ", per bone");
      checked += std::abs(numeric) > 1e-6 ? 1 : 0;
    }
    EXPECT_GT(checked, 15);
  }
  // At the truth the evidence is met: no cost. Off (weight 0), no term at all.
  PoseFitOptions options;
  options.depth_weight = 2;
  EXPECT_LT(DepthTermCost(
                rig, evidence, options, truth.joints, QuaternionOfRotation(truth.cam_from_hand)),
            1e-12);
  EXPECT_EQ(DepthTermCost(rig, evidence, PoseFitOptions(), at.joints, q), 0.0);
}

// Seen along the palm's normal, the index finger bent 0.4 rad towards the camera and bent 0.4 rad
// back (hyperextended) away from it project alike: the landmarks leave the bend where the start
// has it, and the depths turn it the right way.
TEST(PoseFit, DepthEvidenceFlipsAFingersBend) {
  const HandRig rig = ShippedRig();
  Pose truth = TruePose(rig);
  truth.joints[4] = 0.4;  // index MCP flexion: towards the palm, which faces the camera
  truth.joints[5] = 0;    // its abduction, PIP and DIP: a straight finger in one plane
  truth.joints[6] = 0;
  truth.joints[7] = 0;
  auto cam = CamFromHand(rig, {-1, 0.02, 0.03}, 0.2);  // the camera on the palm's side (-x)
  ASSERT_TRUE(cam.ok());
  truth.cam_from_hand = *cam;
  Pose bent_back = truth;
  bent_back.joints[4] = -0.4;
  const PoseFitStart start = StartAt(rig, bent_back);
  PoseFitEvidence evidence = EvidenceOf(Project(rig, truth));
  ASSERT_LT(MaxDistance(Project(rig, bent_back), evidence.landmarks_px), 6.0);
  const double tip_depth = DepthsOf(rig, truth)[8] - DepthsOf(rig, truth)[5];
  ASSERT_LT(tip_depth, -0.2);  // the truth's tip is nearer the camera than its knuckle

  auto landmarks_only = FitPose(rig, start, evidence, PoseFitOptions());
  ASSERT_TRUE(landmarks_only.ok()) << landmarks_only.status().message();
  EXPECT_LT(landmarks_only->joints[4], 0) << "the landmarks alone flipped the bend";

  evidence.has_depths = true;
  evidence.depths = DepthsOf(rig, truth);
  // The weight that crosses the landmarks' ridge between the two bends (at 1 or 3 the fit stays
  // on the start's side).
  PoseFitOptions options;
  options.depth_weight = 10;
  auto with_depths = FitPose(rig, start, evidence, options);
  ASSERT_TRUE(with_depths.ok()) << with_depths.status().message();
  EXPECT_NEAR(with_depths->joints[4], 0.4, 0.1);
  EXPECT_GE(with_depths->depth_cost, 0);
  EXPECT_LT(Error3d(rig, with_depths->joints, with_depths->cam_from_hand, truth),
            Error3d(rig, landmarks_only->joints, landmarks_only->cam_from_hand, truth) / 2);
  EXPECT_NEAR(with_depths->final_cost,
              with_depths->landmark_cost + with_depths->prior_cost + with_depths->depth_cost,
              1e-9 * with_depths->initial_cost);
}

TEST(PoseFit, NonFiniteDepthsAreAnError) {
  const HandRig rig = ShippedRig();
  const Pose truth = TruePose(rig);
  PoseFitEvidence evidence = EvidenceOf(Project(rig, truth));
  evidence.has_depths = true;
  evidence.depths = DepthsOf(rig, truth);
  evidence.depths[12] = std::nanf("");
  auto fit = FitPose(rig, StartAt(rig, truth), evidence, PoseFitOptions());
  ASSERT_FALSE(fit.ok());
  EXPECT_EQ(fit.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(fit.status().message().find("landmark 12: depth"), std::string::npos)
      << fit.status().message();
}

}  // namespace
}  // namespace handdb
