#include "track/smoothing.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace handdb {
namespace {

PoseCandidate Pose(double unary, float joints, double axis = 0) {
  PoseCandidate c;
  c.unary = unary;
  c.joints.fill(joints);
  c.view_direction = {0, 0, 1};
  c.axis_angle = axis;
  return c;
}

// Frame 1's best candidate is a different pose (joints 1.0) by a small margin; frames 0 and 2
// both show joints 0. The path through frame 1's second candidate costs 0.02, the top-1 path
// 2.0 in transitions: the dynamic programming picks the non-top-1 candidate.
TEST(ChooseByDynamicProgramming, PicksTheSteadyPathOverAFlipOfTheTopOne) {
  const std::vector<std::vector<PoseCandidate>> frames = {
      {Pose(0, 0), Pose(0.05, 1)},
      {Pose(0, 1), Pose(0.02, 0)},
      {Pose(0, 0), Pose(0.3, 1)},
  };
  const std::vector<int> choice = ChooseByDynamicProgramming(frames, TransitionCosts{});
  EXPECT_EQ(choice, (std::vector<int>{0, 1, 0}));
  // Without transition costs the frames' own best wins.
  TransitionCosts free;
  free.joint = free.view = free.roll = free.hand = 0;
  EXPECT_EQ(ChooseByDynamicProgramming(frames, free), (std::vector<int>{0, 0, 0}));
}

// A real change of pose that lasts is followed: the unary costs outweigh one transition.
TEST(ChooseByDynamicProgramming, FollowsALastingChangeAndBreaksAtEmptyFrames) {
  std::vector<std::vector<PoseCandidate>> frames;
  for (int t = 0; t < 6; ++t) frames.push_back({Pose(0, t < 3 ? 0 : 1), Pose(0.4, t < 3 ? 1 : 0)});
  EXPECT_EQ(ChooseByDynamicProgramming(frames, TransitionCosts{}),
            (std::vector<int>{0, 0, 0, 0, 0, 0}));
  // An empty frame: -1, and the frames after it are chosen on their own.
  frames.insert(frames.begin() + 2, std::vector<PoseCandidate>{});
  const auto choice = ChooseByDynamicProgramming(frames, TransitionCosts{});
  EXPECT_EQ(choice[2], -1);
  EXPECT_EQ(choice.size(), 7u);
}

TEST(TransitionCost, SumsJointsViewRollAndHand) {
  TransitionCosts c;
  c.joint = 1;
  c.view = 2;
  c.roll = 3;
  c.hand = 4;
  PoseCandidate a = Pose(0, 0, 0.1);
  PoseCandidate b = Pose(0, 0.5, 0.1 - 2 * M_PI + 0.2);  // the same axis turned 0.2 rad
  b.view_direction = {0, 1, 0};                          // 90 degrees away
  b.hand = Hand::kLeft;
  EXPECT_NEAR(TransitionCost(a, b, c), 0.5 + 2 * M_PI / 2 + 3 * 0.2 + 4, 1e-6);
  EXPECT_NEAR(TransitionCost(a, a, c), 0, 1e-9);
}

TEST(CandidatesOf, UnaryFromTheScoreOrTheDistanceRatio) {
  Match a, b;
  a.distance = 2;
  b.distance = 3;
  auto c = CandidatesOf({a, b});
  ASSERT_EQ(c.size(), 2u);
  EXPECT_DOUBLE_EQ(c[0].unary, 0);
  EXPECT_DOUBLE_EQ(c[1].unary, 0.5);
  a.score = 1.2;
  b.score = 1.0;  // re-ranked by landmarks: the score's excess
  c = CandidatesOf({a, b});
  EXPECT_NEAR(c[0].unary, 0.2, 1e-12);
  EXPECT_DOUBLE_EQ(c[1].unary, 0);
}

// A still hand's noisy keypoints come out steadier; a step is followed within a second.
TEST(KeypointFilter, SteadiesAStillHandAndFollowsAMove) {
  KeypointFilter<Keypoints2d> f(KeypointFilterOptions{});
  std::mt19937 rng(1);
  std::normal_distribution<double> noise(0, 2);
  double raw_jitter = 0, out_jitter = 0;
  Keypoints2d prev_raw{}, prev_out{};
  for (int t = 0; t < 60; ++t) {
    Keypoints2d raw;
    for (auto& p : raw)
      p = {static_cast<float>(100 + noise(rng)), static_cast<float>(50 + noise(rng))};
    const Keypoints2d out = f.Filter(raw, t / 30.0);
    if (t > 0) {
      raw_jitter += std::hypot(raw[0].x - prev_raw[0].x, raw[0].y - prev_raw[0].y);
      out_jitter += std::hypot(out[0].x - prev_out[0].x, out[0].y - prev_out[0].y);
    }
    prev_raw = raw;
    prev_out = out;
  }
  EXPECT_LT(out_jitter, raw_jitter / 2);
  Keypoints2d moved;
  for (auto& p : moved) p = {200, 50};
  Keypoints2d out{};
  for (int t = 60; t < 90; ++t) out = f.Filter(moved, t / 30.0);
  EXPECT_NEAR(out[0].x, 200, 5);
}

// The 3D filter treats each coordinate as the 2D one does: the same x and y out of the same x
// and y in, and a noisy still depth steadied.
TEST(KeypointFilter, FiltersThreeDimensionalKeypointsLikeTwoDimensionalOnes) {
  KeypointFilter<Keypoints2d> f2(KeypointFilterOptions{});
  KeypointFilter<Keypoints3d> f3(KeypointFilterOptions{});
  std::mt19937 rng(2);
  std::normal_distribution<double> noise(0, 2);
  double raw_jitter = 0, out_jitter = 0, prev_raw = 0, prev_out = 0;
  for (int t = 0; t < 60; ++t) {
    Keypoints2d raw2;
    Keypoints3d raw3;
    for (int k = 0; k < kNumKeypoints; ++k) {
      raw2[k] = {static_cast<float>(10 * k + noise(rng)), static_cast<float>(5 + noise(rng))};
      raw3[k] = {raw2[k].x, raw2[k].y, static_cast<float>(-20 + noise(rng))};
    }
    const Keypoints2d out2 = f2.Filter(raw2, t / 30.0);
    const Keypoints3d out3 = f3.Filter(raw3, t / 30.0);
    for (int k = 0; k < kNumKeypoints; ++k) {
      EXPECT_FLOAT_EQ(out3[k][0], out2[k].x);
      EXPECT_FLOAT_EQ(out3[k][1], out2[k].y);
    }
    if (t > 0) {
      raw_jitter += std::fabs(raw3[7][2] - prev_raw);
      out_jitter += std::fabs(out3[7][2] - prev_out);
    }
    prev_raw = raw3[7][2];
    prev_out = out3[7][2];
  }
  EXPECT_LT(out_jitter, raw_jitter / 2);
}

TEST(FilterSequence, RunsBetweenGapsAndKeepsGaps) {
  std::vector<std::optional<Keypoints2d>> k(5);
  Keypoints2d a;
  for (auto& p : a) p = {10, 20};
  k[0] = k[1] = k[3] = k[4] = a;
  const auto out = FilterSequence(k, {0, 0.1, 0.2, 0.3, 0.4}, KeypointFilterOptions{});
  EXPECT_FALSE(out[2].has_value());
  ASSERT_TRUE(out[3].has_value());
  EXPECT_FLOAT_EQ((*out[3])[5].x, 10);

  std::vector<std::optional<Keypoints3d>> k3(3);
  Keypoints3d b;
  for (auto& p : b) p = {1, 2, 3};
  k3[0] = k3[2] = b;
  const auto out3 = FilterSequence(k3, {0, 0.1, 0.2}, KeypointFilterOptions{});
  EXPECT_FALSE(out3[1].has_value());
  ASSERT_TRUE(out3[2].has_value());
  EXPECT_FLOAT_EQ((*out3[2])[20][2], 3);
}

}  // namespace
}  // namespace handdb
