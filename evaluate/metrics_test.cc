#include "evaluate/metrics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

namespace handdb {
namespace {

constexpr double kDeg = M_PI / 180.0;

Vec3 DirectionAtDeg(double angle_from_y_deg, double sign_x) {
  return {sign_x * std::sin(angle_from_y_deg * kDeg), std::cos(angle_from_y_deg * kDeg), 0};
}

TEST(JointDistance, KnownValuesForOneJointOff) {
  std::array<float, kNumJointAngles> a{};
  std::array<float, kNumJointAngles> b{};
  b[3] = static_cast<float>(20 * kDeg);
  EXPECT_NEAR(JointDistanceDeg(a, b, JointDistanceKind::kRms), std::sqrt(400.0 / 20.0), 1e-4);
  EXPECT_NEAR(JointDistanceDeg(a, b, JointDistanceKind::kMax), 20.0, 1e-4);
  EXPECT_NEAR(JointDistanceDeg(a, b, JointDistanceKind::kMean), 1.0, 1e-5);
  EXPECT_EQ(JointDistanceDeg(a, a, JointDistanceKind::kRms), 0.0);
}

TEST(JointDistance, NamesRoundTrip) {
  for (auto kind : {JointDistanceKind::kRms, JointDistanceKind::kMax, JointDistanceKind::kMean}) {
    EXPECT_EQ(ParseJointDistanceKind(JointDistanceKindName(kind)), kind);
  }
  EXPECT_FALSE(ParseJointDistanceKind("l2").has_value());
}

TEST(DirectionAngle, KnownAngles) {
  EXPECT_NEAR(DirectionAngleDeg({1, 0, 0}, {0, 1, 0}), 90.0, 1e-9);
  EXPECT_NEAR(DirectionAngleDeg({1, 0, 0}, {1, 0, 0}), 0.0, 1e-9);
  EXPECT_NEAR(DirectionAngleDeg({1, 0, 0}, {-1, 0, 0}), 180.0, 1e-9);
  EXPECT_NEAR(DirectionAngleDeg({2, 0, 0}, {1, 1, 0}), 45.0, 1e-9);
  // Tiny angles stay accurate (acos of a dot product would lose them).
  EXPECT_NEAR(DirectionAngleDeg({1, 0, 0}, {1, 1e-7, 0}), 1e-7 / kDeg, 1e-9);
  EXPECT_NEAR(DirectionAngleDeg(DirectionAtDeg(0, 1), DirectionAtDeg(31, 1)), 31.0, 1e-9);
}

TEST(CircularDifference, WrapsAround) {
  EXPECT_NEAR(CircularDifferenceDeg(350 * kDeg, 10 * kDeg), 20.0, 1e-9);
  EXPECT_NEAR(CircularDifferenceDeg(10 * kDeg, 350 * kDeg), 20.0, 1e-9);
  EXPECT_NEAR(CircularDifferenceDeg(0, M_PI), 180.0, 1e-9);
  EXPECT_NEAR(CircularDifferenceDeg(-170 * kDeg, 170 * kDeg), 20.0, 1e-9);
  EXPECT_NEAR(CircularDifferenceDeg(7.5 * kDeg, 7.5 * kDeg + 4 * M_PI), 0.0, 1e-9);
  EXPECT_NEAR(CircularDifferenceDeg(0, 45 * kDeg), 45.0, 1e-9);
}

void ExpectVecNear(const Vec3& a, const Vec3& b) {
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(a[i], b[i], 1e-9) << "component " << i;
}

TEST(CameraFromHand, FollowsTheUpRuleAndRoll) {
  const HandAxes axes;  // forward +y, palm normal +z
  // Looking at the palm: forward is up in the image (-y of the image), x right.
  CameraAxes cam = CameraFromHand({0, 0, 1}, 0, axes);
  ExpectVecNear(cam.z, {0, 0, -1});
  ExpectVecNear(cam.y, {0, -1, 0});
  ExpectVecNear(cam.x, {1, 0, 0});
  // Roll by 90 degrees: the forward axis (up at roll 0) now points right in the image, as the
  // roll formula x' = c x - s y maps image (0, -1) to (1, 0).
  cam = CameraFromHand({0, 0, 1}, M_PI / 2, axes);
  const Vec3 forward = axes.forward_axis;
  EXPECT_NEAR(forward[0] * cam.x[0] + forward[1] * cam.x[1] + forward[2] * cam.x[2], 1.0, 1e-9);
  EXPECT_NEAR(forward[0] * cam.y[0] + forward[1] * cam.y[1] + forward[2] * cam.y[2], 0.0, 1e-9);
  // Looking along the fingers: up is -palm_normal.
  cam = CameraFromHand({0, 1, 0}, 0, axes);
  ExpectVecNear(cam.y, {0, 0, 1});
  ExpectVecNear(cam.z, {0, -1, 0});
}

TEST(AlignedRoll, EqualsRollDifferenceForEqualDirections) {
  const HandAxes axes;
  const Vec3 d{0.3, -0.5, 0.8};
  const CameraAxes a = CameraFromHand(d, 10 * kDeg, axes);
  const CameraAxes b = CameraFromHand(d, 50 * kDeg, axes);
  EXPECT_NEAR(AlignedRollDifferenceDeg(a, b), 40.0, 1e-6);
  EXPECT_NEAR(AlignedRollDifferenceDeg(b, a), 40.0, 1e-6);
  const CameraAxes c = CameraFromHand(d, 350 * kDeg, axes);
  EXPECT_NEAR(AlignedRollDifferenceDeg(a, c), 20.0, 1e-6);
}

TEST(AlignedRoll, NearbyDirectionsAwayFromThePoleHaveSmallRoll) {
  const HandAxes axes;
  // Two directions 20 degrees apart around the palm normal, both at roll 0.
  const CameraAxes a = CameraFromHand({0, 0, 1}, 0, axes);
  const CameraAxes b = CameraFromHand({std::sin(20 * kDeg), 0, std::cos(20 * kDeg)}, 0, axes);
  EXPECT_NEAR(AlignedRollDifferenceDeg(a, b), 0.0, 1e-6);
}

TEST(AlignedRoll, SeesTheFlipNearTheForwardAxisThatRollLabelsMiss) {
  // Two cameras 24 degrees apart on either side of the forward axis: the up rule makes their
  // images upside down relative to each other although both have camera_roll 0.
  const HandAxes axes;
  const Vec3 d1 = DirectionAtDeg(12, 1);
  const Vec3 d2 = DirectionAtDeg(12, -1);
  EXPECT_NEAR(AlignedRollDifferenceDeg(CameraFromHand(d1, 0, axes), CameraFromHand(d2, 0, axes)),
              180.0,
              1e-6);
  PoseForEval truth;
  truth.view_direction = d1;
  PoseForEval candidate = truth;
  candidate.view_direction = d2;
  CorrectnessOptions options;
  CorrectnessJudge aligned(truth, false, axes, options);
  EXPECT_TRUE(aligned.Judge(candidate).direction_ok);
  EXPECT_FALSE(aligned.Judge(candidate).roll_ok);
  options.roll_compare = RollCompare::kLabel;
  CorrectnessJudge label(truth, false, axes, options);
  EXPECT_TRUE(label.Judge(candidate).roll_ok);
  // Rolling the candidate by 180 degrees makes the images agree again.
  candidate.camera_roll = M_PI;
  EXPECT_TRUE(aligned.IsCorrect(candidate));
}

TEST(CorrectnessJudge, AppliesEachCriterion) {
  const HandAxes axes;
  PoseForEval truth;
  truth.view_direction = {0, 0, 1};
  truth.camera_roll = 0.2;
  CorrectnessOptions options;  // rms, d = 15, 30 deg, 30 deg
  CorrectnessJudge judge(truth, false, axes, options);
  EXPECT_TRUE(judge.IsCorrect(truth));

  PoseForEval shape_off = truth;
  for (auto& j : shape_off.joint_angles) j += static_cast<float>(16 * kDeg);  // rms 16
  EXPECT_FALSE(judge.Judge(shape_off).shape_ok);
  EXPECT_TRUE(judge.Judge(shape_off).direction_ok);
  EXPECT_NEAR(judge.Judge(shape_off).joint_distance_deg, 16.0, 1e-3);
  PoseForEval shape_near = truth;
  for (auto& j : shape_near.joint_angles) j += static_cast<float>(14 * kDeg);
  EXPECT_TRUE(judge.IsCorrect(shape_near));

  PoseForEval dir_off = truth;
  dir_off.view_direction = {std::sin(31 * kDeg), 0, std::cos(31 * kDeg)};
  EXPECT_FALSE(judge.Judge(dir_off).direction_ok);
  dir_off.view_direction = {std::sin(29 * kDeg), 0, std::cos(29 * kDeg)};
  EXPECT_TRUE(judge.IsCorrect(dir_off));

  PoseForEval roll_off = truth;
  roll_off.camera_roll = 0.2 + 31 * kDeg;
  EXPECT_FALSE(judge.IsCorrect(roll_off));
  roll_off.camera_roll = 0.2 - 29 * kDeg;
  EXPECT_TRUE(judge.IsCorrect(roll_off));
  EXPECT_NEAR(judge.Judge(roll_off).roll_deg, 29.0, 1e-6);
}

TEST(CorrectnessJudge, SameShapeModeOnlyForBasicShapeTruth) {
  const HandAxes axes;
  PoseForEval truth;
  PoseForEval near = truth;
  near.joint_angles[0] += static_cast<float>(5 * kDeg);  // rms ~1.1 deg: within d
  CorrectnessOptions options;
  options.same_shape = true;
  EXPECT_FALSE(CorrectnessJudge(truth, true, axes, options).IsCorrect(near));
  EXPECT_TRUE(CorrectnessJudge(truth, true, axes, options).IsCorrect(truth));
  // A PCA-sampled truth has no basic shape to match: d applies.
  EXPECT_TRUE(CorrectnessJudge(truth, false, axes, options).IsCorrect(near));
  options.same_shape = false;
  EXPECT_TRUE(CorrectnessJudge(truth, true, axes, options).IsCorrect(near));
}

TEST(CorrectnessOptions, Check) {
  CorrectnessOptions options;
  EXPECT_TRUE(options.Check());
  options.max_roll_deg = 181;
  EXPECT_FALSE(options.Check());
  options = CorrectnessOptions();
  options.max_joint_distance_deg = -1;
  EXPECT_FALSE(options.Check());
}

TEST(PoseFromLabel, AppliesTheVirtualRoll) {
  ViewLabel label;
  label.view_direction = {0, 0, 1};
  label.keypoints[1] = {10, 0, 3};
  const PoseForEval pose = PoseFromLabel(label, static_cast<float>(M_PI / 2));
  EXPECT_NEAR(pose.camera_roll, M_PI / 2, 1e-6);
  EXPECT_NEAR(pose.keypoints[1][0], 0, 1e-5);
  EXPECT_NEAR(pose.keypoints[1][1], 10, 1e-5);
  EXPECT_NEAR(pose.keypoints[1][2], 3, 1e-6);
}

TEST(KeypointError, RootRelativeInHandSizes) {
  std::array<std::array<float, 3>, kNumKeypoints> a{};
  for (int i = 0; i < kNumKeypoints; ++i) a[i] = {float(i), float(2 * i), float(-i)};
  EXPECT_EQ(KeypointError(a, a), 0.0);
  auto translated = a;
  for (auto& k : translated) k = {k[0] + 50, k[1] - 7, k[2] + 3};
  EXPECT_NEAR(KeypointError(a, translated), 0.0, 1e-6);
  auto shifted = a;
  for (int i = 1; i < kNumKeypoints; ++i) shifted[i][0] += 19.2f;  // a tenth of the diameter
  EXPECT_NEAR(KeypointError(a, shifted), 0.1, 1e-6);
  auto one_off = a;
  one_off[5][2] += 3 * 4 * 192.0f / 5;  // one joint off by 12/5 diameters: mean 0.12
  EXPECT_NEAR(KeypointError(a, one_off), 0.12, 1e-6);
}

TEST(RankBins, BoundariesOfThePapersTable) {
  const std::vector<std::pair<int64_t, int>> cases = {{1, 0},
                                                      {2, 1},
                                                      {4, 1},
                                                      {5, 2},
                                                      {16, 2},
                                                      {17, 3},
                                                      {64, 3},
                                                      {65, 4},
                                                      {256, 4},
                                                      {257, 5},
                                                      {1024, 5},
                                                      {1025, 6},
                                                      {107328, 6},
                                                      {kNoCorrectMatch, 6}};
  for (const auto& [rank, bin] : cases) EXPECT_EQ(RankBin(rank), bin) << "rank " << rank;
  EXPECT_EQ(RankBinName(0), "1");
  EXPECT_EQ(RankBinName(6), ">1024");
}

TEST(Ranks, FirstCorrect) {
  const bool a[] = {false, false, true, true};
  EXPECT_EQ(FirstCorrectRank(a), 3);
  const bool none[] = {false, false};
  EXPECT_EQ(FirstCorrectRank(none), kNoCorrectMatch);
  EXPECT_EQ(FirstCorrectRank({}), kNoCorrectMatch);
  const bool first[] = {true};
  EXPECT_EQ(FirstCorrectRank(first), 1);
}

TEST(Ranks, TableAndSuccess) {
  const std::vector<int64_t> ranks = {1, 1, 3, 20, kNoCorrectMatch, 2000, 300};
  const RankTable table = MakeRankTable(ranks);
  const std::array<int64_t, kNumRankBins> expected = {2, 1, 0, 1, 0, 1, 2};
  EXPECT_EQ(table.counts, expected);
  EXPECT_EQ(table.total(), 7);
  EXPECT_NEAR(SuccessAtN(ranks, 1), 2.0 / 7, 1e-12);
  EXPECT_NEAR(SuccessAtN(ranks, 10), 3.0 / 7, 1e-12);
  EXPECT_NEAR(SuccessAtN(ranks, 100), 4.0 / 7, 1e-12);
  EXPECT_NEAR(SuccessAtN(ranks, 1000), 5.0 / 7, 1e-12);
  EXPECT_NEAR(SuccessAtN(ranks, 1000000), 6.0 / 7, 1e-12);
  EXPECT_EQ(SuccessAtN({}, 1), 0.0);
}

TEST(Summary, MeanMedianQuantilesSkipNaN) {
  const std::vector<double> v = {3, 1, 2, std::numeric_limits<double>::quiet_NaN(), 10};
  const Summary s = Summarise(v);
  EXPECT_EQ(s.count, 4);
  EXPECT_DOUBLE_EQ(s.mean, 4.0);
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.p90, 7.9);
  EXPECT_DOUBLE_EQ(s.min, 1.0);
  EXPECT_DOUBLE_EQ(s.max, 10.0);
  EXPECT_TRUE(std::isnan(Summarise({}).median));
  const auto cdf = EmpiricalCdf(v);
  ASSERT_EQ(cdf.size(), 4u);
  EXPECT_EQ(cdf[0], std::make_pair(1.0, 0.25));
  EXPECT_EQ(cdf[3], std::make_pair(10.0, 1.0));
}

}  // namespace
}  // namespace handdb
