#include "pose/fit_silhouette.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "base/repo_root.h"
#include "generator/hand/camera.h"
#include "generator/hand/rig_testing.h"
#include "photo/image_edges.h"
#include "pose/fit.h"
#include "pose/fit_matches.h"

namespace handdb {
namespace {

using testing::ShippedRig;

// A circle's outline (every pixel centre within half a px of radius `r` around `c`) and the
// same points as edges.
std::vector<Point2f> CircleOutline(Point2f c, double r) {
  std::vector<Point2f> out;
  for (int y = -200; y <= 200; ++y) {
    for (int x = -200; x <= 200; ++x) {
      const double d = std::hypot(x - c.x, y - c.y);
      if (std::abs(d - r) <= 0.5) out.push_back({static_cast<float>(x), static_cast<float>(y)});
    }
  }
  return out;
}

std::vector<PointQ> ToPointQ(const std::vector<Point2f>& points) {
  std::vector<PointQ> out;
  for (const Point2f& p : points) {
    out.push_back({static_cast<int16_t>(std::lround(p.x * kPointScale)),
                   static_cast<int16_t>(std::lround(p.y * kPointScale))});
  }
  return out;
}

float FieldAt(const SilhouetteFields& f, const std::vector<float>& field, double x, double y) {
  const int ix = static_cast<int>(std::lround((x - f.origin_px) / f.cell_px));
  const int iy = static_cast<int>(std::lround((y - f.origin_px) / f.cell_px));
  return field[static_cast<size_t>(iy) * f.size + ix];
}

TEST(SilhouetteFields, AreTheDistancesToTheEnclosedRegionAndToTheEdges) {
  const std::vector<Point2f> outline = CircleOutline({10, -5}, 60);
  auto fields = MakeSilhouetteFields(outline, ToPointQ(outline));
  ASSERT_TRUE(fields.ok()) << fields.status().ToString();
  // Inside the circle: no distance to the region; the edges are 60 px from the centre.
  EXPECT_EQ(FieldAt(*fields, fields->outside_hand, 10, -5), 0.0f);
  EXPECT_NEAR(FieldAt(*fields, fields->edges, 10, -5), 60.0, 1.0);
  // 30 px outside it, both are ~30 px (the region's edge within a region cell of the outline).
  EXPECT_NEAR(FieldAt(*fields, fields->outside_hand, 100, -5), 30.0, 2.0);
  EXPECT_NEAR(FieldAt(*fields, fields->edges, 100, -5), 30.0, 1.0);
  // The outline is thinned to about one point per 6 px of its 377 px.
  EXPECT_GT(fields->outline.size(), 40u);
  EXPECT_LT(fields->outline.size(), 120u);
}

TEST(SilhouetteFields, RefuseAnEmptyOutlineOrNoEdges) {
  const std::vector<Point2f> outline = CircleOutline({0, 0}, 40);
  EXPECT_EQ(MakeSilhouetteFields({}, ToPointQ(outline)).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(MakeSilhouetteFields(outline, {}).status().code(), StatusCode::kInvalidArgument);
  SilhouetteFieldOptions bad;
  bad.region_cell_px = 0;
  EXPECT_FALSE(bad.Check());
  EXPECT_TRUE(SilhouetteFieldOptions{}.Check());
}

TEST(HandCapsules, ProjectOntoTheRigsKeypointsWithTheFitsCamera) {
  const HandRig rig = ShippedRig();
  const std::vector<HandCapsule> capsules = HandCapsules(rig);
  ASSERT_EQ(capsules.size(), 21u);
  // A start with no evidence is the start: its keypoints are the rig's, projected.
  PoseFitStart start;
  for (int i = 0; i < kNumJointAngles; ++i) {
    start.joints[i] = 0.5 * (rig.limits().min[i] + rig.limits().max[i]);
  }
  start.view_direction = {0.3, -0.2, 0.93};
  start.roll = 0.4;
  auto cam = CamFromHand(rig, start.view_direction, start.roll);
  ASSERT_TRUE(cam.ok());
  const HandKeypoints3d points = rig.Keypoints3d(start.joints);
  for (int k = 0; k < kNumKeypoints; ++k) {
    double xy[2] = {0, 0};
    for (int r = 0; r < 2; ++r) {
      for (int c = 0; c < 3; ++c) xy[r] += (*cam)[r][c] * (points[k][c] - rig.look_at()[c]);
    }
    start.keypoints_normalised[k] = {static_cast<float>(900 * xy[0] + 3),
                                     static_cast<float>(900 * xy[1] - 7)};
  }
  auto fit = FitPose(rig, start, PoseFitEvidence{}, PoseFitOptions{});
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  const std::vector<ProjectedCapsule> projected = ProjectCapsules(
      capsules, fit->keypoints_in_hand, fit->cam_from_hand, rig.look_at(), fit->scale, fit->shift);
  ASSERT_EQ(projected.size(), capsules.size());
  for (size_t i = 0; i < capsules.size(); ++i) {
    const Point2f& a = fit->keypoints_normalised[capsules[i].from];
    const Point2f& b = fit->keypoints_normalised[capsules[i].to];
    EXPECT_NEAR(projected[i].from.x, a.x, 1e-3);
    EXPECT_NEAR(projected[i].from.y, a.y, 1e-3);
    EXPECT_NEAR(projected[i].to.x, b.x, 1e-3);
    EXPECT_NEAR(projected[i].to.y, b.y, 1e-3);
    EXPECT_NEAR(projected[i].radius, capsules[i].radius * fit->scale, 1e-9);
  }
  // A finger is a few px wide at the normalised hand's 192 px: 5-20 px across.
  EXPECT_NEAR(fit->scale, 900, 1e-6);
  for (const ProjectedCapsule& c : projected) {
    EXPECT_GT(2 * c.radius, 5.0);
    EXPECT_LT(2 * c.radius, 40.0);
  }
}

// The label render of a natural-pose test view (its truth below) as a label picture.
class LabelRenderFit : public ::testing::Test {
 protected:
  void SetUp() override {
    PictureOptions options;
    options.edges.kind = QueryInputKind::kLabels;
    auto picture = ReadPicture(RepoRoot() / "tests/data/labels/natural-00000.exr", options);
    ASSERT_TRUE(picture.ok()) << picture.status().ToString();
    picture_ = std::move(picture).value();
    auto fields = PictureSilhouetteFields(picture_, SilhouetteFieldOptions{});
    ASSERT_TRUE(fields.ok()) << fields.status().ToString();
    fields_ = std::make_shared<const SilhouetteFields>(std::move(fields).value());
    truth_joints_ = {0.042593634,
                     -0.232514624,
                     0.0567914713,
                     0.0638904103,
                     0.268217918,
                     0.044247343,
                     0.327821938,
                     0.268217918,
                     0.235027351,
                     0.0522683552,
                     0.287255684,
                     0.235027351,
                     -0.0517732239,
                     -0.0451389315,
                     0,
                     -0.0517732239,
                     -0.236334272,
                     0.0239587479,
                     0,
                     -0.174533};
    truth_direction_ = {0.7931246690463406, 0.5993853403234274, 0.10812249144142894};
    truth_roll_ = 3.4366388444086935;
    const double kps[kNumKeypoints][2] = {
        {12.4368, -80.6961}, {33.5362, -38.2772},  {42.3022, -8.3547},  {49.7655, 22.6838},
        {54.8449, 35.8586},  {8.92381, 7.37845},   {5.62904, 47.6139},  {8.83777, 65.8772},
        {10.8504, 73.5975},  {-10.2708, 3.61847},  {-14.9445, 44.956},  {-12.5344, 66.5361},
        {-11.0618, 75.8265}, {-19.7421, -7.78694}, {-35.7456, 28.6644}, {-45.7649, 50.9679},
        {-50.7225, 61.0994}, {-25.1703, -21.965},  {-43.2881, 5.02747}, {-55.1579, 19.5449},
        {-63.2694, 27.5608}};
    for (int k = 0; k < kNumKeypoints; ++k) {
      truth_keypoints_[k] = {static_cast<float>(kps[k][0]), static_cast<float>(kps[k][1])};
    }
  }

  // Root-relative 3D keypoint error in the camera frame, in the truth's wrist-to-middle-knuckle
  // lengths (evaluate/'s keypoint error up to its frame).
  double Error3d(const HandRig& rig, const JointVector& joints, const Mat3d& cam_from_hand) const {
    const auto in_cam = [&](const JointVector& j, const Mat3d& r) {
      const HandKeypoints3d p = rig.Keypoints3d(j);
      HandKeypoints3d out;
      for (int k = 0; k < kNumKeypoints; ++k) {
        for (int a = 0; a < 3; ++a) {
          out[k][a] = 0;
          for (int c = 0; c < 3; ++c) out[k][a] += r[a][c] * (p[k][c] - p[0][c]);
        }
      }
      return out;
    };
    const HandKeypoints3d a = in_cam(joints, cam_from_hand);
    const HandKeypoints3d b =
        in_cam(truth_joints_, CamFromHand(rig, truth_direction_, truth_roll_).value());
    const double unit = std::hypot(b[9][0], b[9][1], b[9][2]);
    double sum = 0;
    for (int k = 1; k < kNumKeypoints; ++k) {
      sum += std::hypot(a[k][0] - b[k][0], a[k][1] - b[k][1], a[k][2] - b[k][2]);
    }
    return sum / (kNumKeypoints - 1) / unit;
  }

  PictureEvidence picture_;
  std::shared_ptr<const SilhouetteFields> fields_;
  JointVector truth_joints_{};
  Vec3d truth_direction_{};
  double truth_roll_ = 0;
  NormalisedKeypoints2d truth_keypoints_{};
};

TEST_F(LabelRenderFit, WithoutLandmarksImprovesAPerturbedCandidate) {
  const HandRig rig = ShippedRig();
  PoseFitStart start;
  // A neighbour the search might return: every joint 0.25 rad further (clamped into the
  // limits) and the camera rolled by 0.15 rad. (The silhouette is 2D: a candidate off in its
  // joints alone, at the right rotation, is not always moved nearer in 3D.)
  start.joints = truth_joints_;
  for (int i = 0; i < kNumJointAngles; ++i) start.joints[i] += 0.25;
  start.view_direction = truth_direction_;
  start.roll = truth_roll_ + 0.15;
  start.keypoints_normalised = truth_keypoints_;
  JointVector clamped = start.joints;
  rig.limits().Clamp(&clamped);
  const double before =
      Error3d(rig, clamped, CamFromHand(rig, start.view_direction, start.roll).value());

  PoseFitEvidence evidence;  // no landmarks
  evidence.silhouette = fields_;
  auto fit = FitPose(rig, start, evidence, PoseFitOptions{});
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  EXPECT_NE(fit->termination, "FAILURE") << fit->message;
  EXPECT_GT(fit->iterations, 1);
  EXPECT_EQ(fit->landmark_cost, 0);
  EXPECT_GT(fit->silhouette_cost, 0);
  EXPECT_LT(fit->final_cost, fit->initial_cost);
  const double after = Error3d(rig, fit->joints, fit->cam_from_hand);
  EXPECT_LT(after, 0.8 * before) << "before " << before << ", after " << after;
}

TEST_F(LabelRenderFit, SilhouetteGradientMatchesNumericDifferences) {
  const HandRig rig = ShippedRig();
  JointVector joints = truth_joints_;
  for (int i = 0; i < kNumJointAngles; ++i) joints[i] += i % 3 == 0 ? 0.2 : -0.1;
  const Mat3d cam = CamFromHand(rig, truth_direction_, truth_roll_ + 0.1).value();
  // cam_from_hand as a unit quaternion (w, x, y, z).
  const double w = 0.5 * std::sqrt(std::max(0.0, 1 + cam[0][0] + cam[1][1] + cam[2][2]));
  ASSERT_GT(w, 0.1);
  std::array<double, 4> q = {w,
                             (cam[2][1] - cam[1][2]) / (4 * w),
                             (cam[0][2] - cam[2][0]) / (4 * w),
                             (cam[1][0] - cam[0][1]) / (4 * w)};
  double scale = 1000;
  std::array<double, 2> shift = {4, -3};
  const PoseFitOptions options;
  std::vector<double> gradient;
  const double cost =
      SilhouetteTermCost(rig, *fields_, false, options, joints, q, scale, shift, &gradient);
  ASSERT_EQ(gradient.size(), static_cast<size_t>(kNumJointAngles + 4 + 1 + 2));
  EXPECT_GT(cost, 0);
  // Central differences of the same function, parameter by parameter.
  const auto at = [&](int i, double h) {
    JointVector j = joints;
    std::array<double, 4> qq = q;
    double s = scale;
    std::array<double, 2> t = shift;
    if (i < kNumJointAngles) {
      j[i] += h;
    } else if (i < kNumJointAngles + 4) {
      qq[i - kNumJointAngles] += h;
    } else if (i == kNumJointAngles + 4) {
      s += h;
    } else {
      t[i - kNumJointAngles - 5] += h;
    }
    return SilhouetteTermCost(rig, *fields_, false, options, j, qq, s, t);
  };
  int checked = 0;
  for (int i = 0; i < static_cast<int>(gradient.size()); ++i) {
    const double h = i == kNumJointAngles + 4 ? 1e-3 : (i > kNumJointAngles + 4 ? 1e-4 : 1e-6);
    const double numeric = (at(i, h) - at(i, -h)) / (2 * h);
    EXPECT_NEAR(gradient[i], numeric, 1e-3 * std::abs(numeric) + 1e-4 * (1 + std::abs(cost)))
        << "parameter " << i;
    checked += std::abs(numeric) > 1e-6 ? 1 : 0;
  }
  EXPECT_GT(checked, 10);  // the term depends on most parameters
}

TEST(PictureSilhouetteFields, AnEmptyMaskLeavesTheMatchUnfittedWithAReason) {
  PictureEvidence empty;
  empty.edges.scale = 1.0;
  EXPECT_FALSE(PictureSilhouetteFields(empty, SilhouetteFieldOptions{}).ok());
}

}  // namespace
}  // namespace handdb
