#include "pose/fit_matches.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "generator/hand/camera.h"
#include "generator/hand/rig_testing.h"

namespace handdb {
namespace {

constexpr uint32_t kRolls = 12;

DatabaseRig ShippedRig() {
  DatabaseRig out{testing::ShippedRig(), RenderSettings{}, {}, false};
  out.render.resolution = 256;
  out.render.ortho_scale = out.rig.model().ortho_scale > 0 ? out.rig.model().ortho_scale : 0.25;
  return out;
}

// A stored view of the rig: joints, view direction, no camera roll, normalised as the converter
// would (its centre and scale chosen here; the fit only needs them recorded).
ViewLabel StoredLabel(const DatabaseRig& rig, const JointVector& joints, const Vec3d& direction) {
  ViewLabel l;
  l.render_id = 0;
  l.shape_id = 0;
  l.dir_id = 0;
  for (int i = 0; i < kNumJointAngles; ++i) l.joint_angles[i] = static_cast<float>(joints[i]);
  for (int c = 0; c < 3; ++c) l.view_direction[c] = static_cast<float>(direction[c]);
  l.scale = 1.5f;
  l.source_centre_px = {128.0f, 130.0f};
  l.source_diameter_px = 128.0f;
  auto kps = ViewKeypointsNormalised(rig.rig, l, rig.render, 0.0);
  THROW_CHECK(kps.ok());
  for (int k = 0; k < kNumKeypoints; ++k) {
    for (int c = 0; c < 3; ++c) l.keypoints[k][c] = static_cast<float>((*kps)[k][c]);
  }
  return l;
}

// A picture whose landmarks are the truth's keypoints in the normalised frame (the picture's
// frame is the normalised one: scale 1, centre 0), x mirrored for a left hand.
PictureEvidence PictureOf(const ViewKeypoints& truth, bool left, float presence) {
  PictureEvidence p;
  p.edges.scale = 1.0;
  p.edges.centre_x = 0.0;
  p.edges.centre_y = 0.0;
  HandLandmarks l;
  for (int k = 0; k < kNumKeypoints; ++k) {
    const double x = left ? -truth[k][0] : truth[k][0];
    // ImageFromNormalised puts pixel centres at +0.5 nowhere here: scale 1, centre 0.
    l.image_px[k] = {static_cast<float>(x), static_cast<float>(truth[k][1])};
  }
  l.presence = presence;
  p.landmarks = l;
  return p;
}

double MeanDistance2d(const std::array<Point2f, kNumKeypoints>& a, const ViewKeypoints& b) {
  double sum = 0;
  for (int k = 0; k < kNumKeypoints; ++k) sum += std::hypot(a[k].x - b[k][0], a[k].y - b[k][1]);
  return sum / kNumKeypoints;
}

class FitMatchesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    rig_ = ShippedRig();
    JointVector joints{};
    for (int i = 0; i < kNumJointAngles; ++i) {
      const auto& lim = rig_.rig.limits();
      joints[i] = 0.5 * (lim.min[i] + lim.max[i]);
    }
    start_joints_ = joints;
    const Vec3d direction{0.3, -0.2, 0.93};
    const double n = std::sqrt(0.3 * 0.3 + 0.2 * 0.2 + 0.93 * 0.93);
    direction_ = {direction[0] / n, direction[1] / n, direction[2] / n};
    db_.emplace(Database::FromMemory(
        {StoredLabel(rig_, joints, direction_)}, {{{0, 0}, {16, 0}}}, kRolls, {"test"}));
    // The truth: every joint moved 0.15 rad inside its limits, the same view rolled by roll 2.
    truth_joints_ = joints;
    for (int i = 0; i < kNumJointAngles; ++i) truth_joints_[i] += i % 2 == 0 ? 0.15 : -0.15;
    rig_.rig.limits().Clamp(&truth_joints_);
    ViewLabel truth = StoredLabel(rig_, truth_joints_, direction_);
    auto kps = ViewKeypointsNormalised(rig_.rig, truth, rig_.render, RollAngle(2, kRolls));
    THROW_CHECK(kps.ok());
    truth_ = *kps;
  }

  Match MatchOf(Hand hand) const {
    Match m;
    m.view_id = 0;
    m.roll = 2;
    m.roll_angle = RollAngle(2, kRolls);
    m.hand = hand;
    m.label = RollLabel(db_->label(0), m.roll_angle);
    if (hand == Hand::kLeft) m.label = MirrorLabel(m.label);
    return m;
  }

  DatabaseRig rig_;
  JointVector start_joints_{}, truth_joints_{};
  Vec3d direction_{};
  std::optional<Database> db_;
  ViewKeypoints truth_{};
};

TEST_F(FitMatchesTest, MovesTheMatchOntoTheLandmarks) {
  const PictureEvidence picture = PictureOf(truth_, /*left=*/false, 0.99f);
  auto fit = FitPictureMatches(rig_, *db_, picture, {MatchOf(Hand::kRight)}, MatchFitOptions{});
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  ASSERT_EQ(fit->fits.size(), 1u);
  ASSERT_EQ(fit->best, 0);
  const MatchFit& f = fit->fits[0];
  ASSERT_TRUE(f.fitted) << f.reason;
  EXPECT_TRUE(f.fit.converged) << f.fit.termination << ": " << f.fit.message;
  // The match starts several px off and ends on the landmarks (within the prior's pull).
  EXPECT_GT(f.landmark_error_start_px, 3.0);
  EXPECT_LT(f.landmark_error_px, 0.5);
  EXPECT_LT(MeanDistance2d(f.keypoints_image_px, truth_), 0.5);
  // The fitted depths are the labels' convention: the truth's own z, up to the prior's pull.
  double dz = 0;
  for (int k = 0; k < kNumKeypoints; ++k) {
    dz += std::abs((f.keypoints_3d[k][2] - f.keypoints_3d[0][2]) - (truth_[k][2] - truth_[0][2]));
  }
  EXPECT_LT(dz / kNumKeypoints, 2.0);
}

// Matches fitted on several threads are the fits of one thread, and the same one is the answer.
TEST_F(FitMatchesTest, ThreadsGiveTheSameFits) {
  const PictureEvidence picture = PictureOf(truth_, /*left=*/false, 0.99f);
  const std::vector<Match> matches = {
      MatchOf(Hand::kRight), MatchOf(Hand::kLeft), MatchOf(Hand::kRight), MatchOf(Hand::kLeft)};
  MatchFitOptions options;
  options.max_matches = 4;
  auto one = FitPictureMatches(rig_, *db_, picture, matches, options);
  options.num_threads = 3;
  auto three = FitPictureMatches(rig_, *db_, picture, matches, options);
  ASSERT_TRUE(one.ok()) << one.status().ToString();
  ASSERT_TRUE(three.ok()) << three.status().ToString();
  ASSERT_EQ(one->fits.size(), 4u);
  ASSERT_EQ(three->fits.size(), 4u);
  EXPECT_EQ(one->best, three->best);
  for (size_t i = 0; i < 4; ++i) {
    ASSERT_TRUE(one->fits[i].fitted) << one->fits[i].reason;
    ASSERT_TRUE(three->fits[i].fitted) << three->fits[i].reason;
    EXPECT_EQ(one->fits[i].fit.final_cost, three->fits[i].fit.final_cost) << "match " << i;
    EXPECT_EQ(one->fits[i].fit.joints, three->fits[i].fit.joints) << "match " << i;
  }
  options.num_threads = 0;
  EXPECT_FALSE(FitPictureMatches(rig_, *db_, picture, matches, options).ok());
}

TEST_F(FitMatchesTest, ALeftHandIsFittedInTheMirroredPictureAndMirroredBack) {
  const PictureEvidence picture = PictureOf(truth_, /*left=*/true, 0.99f);
  auto fit = FitPictureMatches(rig_, *db_, picture, {MatchOf(Hand::kLeft)}, MatchFitOptions{});
  ASSERT_TRUE(fit.ok());
  const MatchFit& f = fit->fits[0];
  ASSERT_TRUE(f.fitted) << f.reason;
  ViewKeypoints mirrored = truth_;
  for (auto& k : mirrored) k[0] = -k[0];
  EXPECT_LT(MeanDistance2d(f.keypoints_image_px, mirrored), 0.5);
  // The rotation is in the left hand's frame: still a rotation (determinant +1).
  const Mat3d& r = f.fit.cam_from_hand;
  const double det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) -
                     r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0]) +
                     r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
  EXPECT_NEAR(det, 1.0, 1e-9);
  // Mirroring it back gives the right hand's camera; twice, the rotation itself.
  EXPECT_EQ(MirrorCamFromHand(MirrorCamFromHand(r)), r);
  EXPECT_NE(MirrorCamFromHand(r), r);
}

TEST_F(FitMatchesTest, WithoutUsableLandmarksTheMatchStandsWithAReason) {
  PictureEvidence none = PictureOf(truth_, false, 0.99f);
  none.landmarks.reset();
  auto fit = FitPictureMatches(rig_, *db_, none, {MatchOf(Hand::kRight)}, MatchFitOptions{});
  ASSERT_TRUE(fit.ok());
  EXPECT_EQ(fit->best, -1);
  EXPECT_FALSE(fit->fits[0].fitted);
  // The picture has neither landmarks nor a hand region (no outline pixels): nothing to fit to.
  EXPECT_EQ(fit->fits[0].reason.rfind("no landmarks and no silhouette (", 0), 0u)
      << fit->fits[0].reason;

  const PictureEvidence weak = PictureOf(truth_, false, 0.2f);
  fit = FitPictureMatches(rig_, *db_, weak, {MatchOf(Hand::kRight)}, MatchFitOptions{});
  ASSERT_TRUE(fit.ok());
  EXPECT_FALSE(fit->fits[0].fitted);
  EXPECT_NE(fit->fits[0].reason.find("presence 0.2 below 0.5"), std::string::npos)
      << fit->fits[0].reason;

  // NaN landmarks are refused by the fit and reported, never thrown.
  PictureEvidence bad = PictureOf(truth_, false, 0.99f);
  bad.landmarks->image_px[3].x = std::nanf("");
  fit = FitPictureMatches(rig_, *db_, bad, {MatchOf(Hand::kRight)}, MatchFitOptions{});
  ASSERT_TRUE(fit.ok());
  EXPECT_FALSE(fit->fits[0].fitted);
  EXPECT_FALSE(fit->fits[0].reason.empty());
}

// The network's world joints give the depth term its evidence; a NaN among them leaves the match
// unfitted with the reason when the term is on, and does not matter when it is off.
TEST_F(FitMatchesTest, NanWorldLandmarksLeaveTheMatchUnfittedWithAReason) {
  PictureEvidence picture = PictureOf(truth_, false, 0.99f);
  picture.landmarks->has_world = true;
  for (int k = 0; k < kNumKeypoints; ++k) {
    picture.landmarks->world_m[k] = {0.01f * k, 0.0f, 0.002f * k};
  }
  MatchFitOptions options;
  options.fit.depth_weight = 1;
  auto fit = FitPictureMatches(rig_, *db_, picture, {MatchOf(Hand::kRight)}, options);
  ASSERT_TRUE(fit.ok());
  ASSERT_TRUE(fit->fits[0].fitted) << fit->fits[0].reason;
  EXPECT_GT(fit->fits[0].fit.depth_cost, 0);

  picture.landmarks->world_m[6][2] = std::nanf("");
  fit = FitPictureMatches(rig_, *db_, picture, {MatchOf(Hand::kRight)}, options);
  ASSERT_TRUE(fit.ok());
  EXPECT_EQ(fit->best, -1);
  EXPECT_FALSE(fit->fits[0].fitted);
  EXPECT_NE(fit->fits[0].reason.find("landmark 6: depth"), std::string::npos)
      << fit->fits[0].reason;

  fit = FitPictureMatches(rig_, *db_, picture, {MatchOf(Hand::kRight)}, MatchFitOptions{});
  ASSERT_TRUE(fit.ok());
  EXPECT_TRUE(fit->fits[0].fitted) << fit->fits[0].reason;
  EXPECT_EQ(fit->fits[0].fit.depth_cost, 0);
}

TEST_F(FitMatchesTest, WithoutLandmarksTheSilhouetteIsFitted) {
  // The picture's hand region: the truth's capsules (the fit's own model) drawn as an outline.
  PictureEvidence picture = PictureOf(truth_, false, 0.99f);
  picture.landmarks.reset();
  const HandKeypoints3d points = rig_.rig.Keypoints3d(truth_joints_);
  auto start = PoseFitStartFromLabel(rig_.rig, db_->label(0), rig_.render, RollAngle(2, kRolls));
  ASSERT_TRUE(start.ok());
  auto at_truth = FitPose(rig_.rig,
                          {truth_joints_, start->view_direction, start->roll, {}},
                          PoseFitEvidence{},
                          PoseFitOptions{});
  // (keypoints {} would give no scale: take the truth's own)
  PoseFitStart truth_start = *start;
  truth_start.joints = truth_joints_;
  for (int k = 0; k < kNumKeypoints; ++k) {
    truth_start.keypoints_normalised[k] = {static_cast<float>(truth_[k][0]),
                                           static_cast<float>(truth_[k][1])};
  }
  at_truth = FitPose(rig_.rig, truth_start, PoseFitEvidence{}, PoseFitOptions{});
  ASSERT_TRUE(at_truth.ok()) << at_truth.status().ToString();
  const std::vector<ProjectedCapsule> capsules = ProjectCapsules(HandCapsules(rig_.rig),
                                                                 points,
                                                                 at_truth->cam_from_hand,
                                                                 rig_.rig.look_at(),
                                                                 at_truth->scale,
                                                                 at_truth->shift);
  // The outline of the union is the silhouette; each capsule's own outline inside it stands for
  // the label render's occlusion edges between links.
  const auto in_capsule = [&](const ProjectedCapsule& c, int px, int py) {
    const double dx = c.to.x - c.from.x, dy = c.to.y - c.from.y;
    const double ex = px + 0.5 - c.from.x, ey = py + 0.5 - c.from.y;
    const double t = std::clamp((ex * dx + ey * dy) / (dx * dx + dy * dy + 1e-9), 0.0, 1.0);
    return std::hypot(ex - t * dx, ey - t * dy) <= c.radius;
  };
  const auto inside = [&](int px, int py) {
    return std::any_of(capsules.begin(), capsules.end(), [&](const ProjectedCapsule& c) {
      return in_capsule(c, px, py);
    });
  };
  for (int y = -150; y <= 150; ++y) {
    for (int x = -150; x <= 150; ++x) {
      if (!inside(x, y)) continue;
      if (!inside(x - 1, y) || !inside(x + 1, y) || !inside(x, y - 1) || !inside(x, y + 1)) {
        picture.edges.contour_pixels.push_back({x, y});
      }
      for (const ProjectedCapsule& c : capsules) {
        if (in_capsule(c, x, y) && (!in_capsule(c, x - 1, y) || !in_capsule(c, x + 1, y) ||
                                    !in_capsule(c, x, y - 1) || !in_capsule(c, x, y + 1))) {
          picture.edges.points.push_back({static_cast<int16_t>((x + 0.5) * kPointScale),
                                          static_cast<int16_t>((y + 0.5) * kPointScale)});
          break;
        }
      }
    }
  }
  MatchFitOptions on;
  on.use_silhouette = true;  // off by default (docs/decisions/0016)
  auto fit = FitPictureMatches(rig_, *db_, picture, {MatchOf(Hand::kRight)}, on);
  ASSERT_TRUE(fit.ok());
  EXPECT_FALSE(fit->landmarks_used);
  EXPECT_TRUE(fit->silhouette_used);
  ASSERT_EQ(fit->best, 0);
  const MatchFit& f = fit->fits[0];
  ASSERT_TRUE(f.fitted) << f.reason;
  EXPECT_GT(f.fit.silhouette_cost, 0);
  EXPECT_EQ(f.fit.landmark_cost, 0);
  EXPECT_LT(f.fit.final_cost, f.fit.initial_cost);
  // The keypoints move towards the truth's (the start is several px off).
  double start_px = 0;
  for (int k = 0; k < kNumKeypoints; ++k) {
    start_px += std::hypot(start->keypoints_normalised[k].x - truth_[k][0],
                           start->keypoints_normalised[k].y - truth_[k][1]);
  }
  EXPECT_LT(MeanDistance2d(f.keypoints_image_px, truth_), start_px / kNumKeypoints);

  // The silhouette term off (the default): nothing to fit to, and the reason says so.
  fit = FitPictureMatches(rig_, *db_, picture, {MatchOf(Hand::kRight)}, MatchFitOptions{});
  ASSERT_TRUE(fit.ok());
  EXPECT_EQ(fit->best, -1);
  EXPECT_NE(fit->fits[0].reason.find("the silhouette term is off"), std::string::npos);
}

TEST_F(FitMatchesTest, FitsOnlyTheFirstMatchesAndAnswersWithTheFirstFitted) {
  const PictureEvidence picture = PictureOf(truth_, false, 0.99f);
  const std::vector<Match> matches = {
      MatchOf(Hand::kRight), MatchOf(Hand::kRight), MatchOf(Hand::kRight)};
  MatchFitOptions options;
  options.max_matches = 2;
  auto fit = FitPictureMatches(rig_, *db_, picture, matches, options);
  ASSERT_TRUE(fit.ok());
  EXPECT_EQ(fit->fits.size(), 2u);
  EXPECT_EQ(fit->best, 0);

  options.max_matches = -1;
  EXPECT_FALSE(FitPictureMatches(rig_, *db_, picture, matches, options).ok());
}

}  // namespace
}  // namespace handdb
