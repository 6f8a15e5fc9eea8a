#include "query/chamfer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace handdb {
namespace {

std::vector<PointQ> RandomPoints(size_t n, int range, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> u(-range, range);
  std::vector<PointQ> pts(n);
  for (auto& p : pts) p = {static_cast<int16_t>(u(rng)), static_cast<int16_t>(u(rng))};
  return pts;
}

std::vector<Point2f> ToPx(std::span<const PointQ> pts) {
  std::vector<Point2f> out;
  for (const auto& p : pts) out.push_back({PointQToPx(p.x), PointQToPx(p.y)});
  return out;
}

TEST(Chamfer, KdTreesMatchBruteForceForBothBackends) {
  for (uint32_t seed = 0; seed < 5; ++seed) {
    const auto q = RandomPoints(200 + seed * 50, 150 * 16, seed);
    const auto y = RandomPoints(300, 150 * 16, seed + 100);
    const ChamferTerms ref = ChamferBruteForce(q, y);
    for (KdTreeBackend backend : {KdTreeBackend::kNanoflann, KdTreeBackend::kPcl}) {
      const KdTree qt(q, backend);
      const KdTree yt(y, backend);
      const ChamferTerms got = Chamfer(q, qt, y, yt);
      EXPECT_EQ(got.a, ref.a);
      EXPECT_EQ(got.b, ref.b);
    }
    EXPECT_GT(ref.a, 0);
    EXPECT_GT(ref.b, 0);
  }
}

TEST(Chamfer, KnownValues) {
  // Q = {(0,0)}, Y = {(3,4) px, (6,8) px}: A = 5, B = (5 + 10) / 2.
  const std::vector<PointQ> q = {{0, 0}};
  const std::vector<PointQ> y = {{48, 64}, {96, 128}};
  const ChamferTerms t = ChamferBruteForce(q, y);
  EXPECT_DOUBLE_EQ(t.a, 5.0);
  EXPECT_DOUBLE_EQ(t.b, 7.5);
  EXPECT_DOUBLE_EQ(t.total(), 12.5);
}

TEST(RotateAndQuantise, RoundTripsRolledViewPointsExactly) {
  // A roll of canonical points (format/roll.h) rotated back lands on the same PointQ.
  const auto y = RandomPoints(500, 166 * 16, 9);
  for (int r = 0; r < 48; ++r) {
    const float a = RollAngle(r, 48);
    std::vector<Point2f> rolled;
    RollPoints(y, a, &rolled);
    const auto back = RotateAndQuantise(rolled, -a);
    ASSERT_EQ(back.size(), y.size());
    for (size_t i = 0; i < y.size(); ++i) {
      ASSERT_EQ(back[i].x, y[i].x) << r;
      ASSERT_EQ(back[i].y, y[i].y) << r;
    }
  }
}

TEST(RotateAndQuantise, RoundsAndClamps) {
  const std::vector<Point2f> px = {{0.03f, -0.03f}, {1.0f / 32 + 1e-4f, 0}, {5000, -5000}};
  const auto q = Quantise(px);
  EXPECT_EQ(q[0].x, 0);
  EXPECT_EQ(q[0].y, 0);
  EXPECT_EQ(q[1].x, 1);
  EXPECT_EQ(q[2].x, 32767);
  EXPECT_EQ(q[2].y, -32768);
  const auto r =
      RotateAndQuantise(ToPx(std::vector<PointQ>{{160, 0}}), static_cast<float>(M_PI / 2));
  EXPECT_EQ(r[0].x, 0);
  EXPECT_EQ(r[0].y, 160);  // +x turns towards +y
}

TEST(NearestSquaredSmall, MatchesTheKdTreeForEverySizeAndTheCoordinateLimit) {
  std::mt19937 rng(11);
  for (size_t n : {1, 7, 8, 9, 15, 16, 17, 23, 24, 25, 31, 555, 1000}) {
    std::uniform_int_distribution<int> u(-kSmallCoordLimit, kSmallCoordLimit);
    std::vector<PointQ> pts(n);
    for (auto& p : pts) p = {static_cast<int16_t>(u(rng)), static_cast<int16_t>(u(rng))};
    // Extremes of the documented range, where a 32-bit squared distance is closest to overflow.
    pts[0] = {static_cast<int16_t>(kSmallCoordLimit), static_cast<int16_t>(kSmallCoordLimit)};
    const KdTree tree(pts, KdTreeBackend::kNanoflann);
    for (int i = 0; i < 200; ++i) {
      PointQ q{static_cast<int16_t>(u(rng)), static_cast<int16_t>(u(rng))};
      if (i == 0)
        q = {static_cast<int16_t>(-kSmallCoordLimit), static_cast<int16_t>(-kSmallCoordLimit)};
      ASSERT_EQ(NearestSquaredSmall(q, pts), tree.NearestSquared(q)) << "n " << n << " i " << i;
    }
  }
}

TEST(NearestSquaredSmall, ReadsNoPointPastTheSpan) {
  // The point just past each span is the query itself: counting it would give 0.
  std::vector<PointQ> pts(64);
  for (size_t i = 0; i < pts.size(); ++i) {
    pts[i] = {static_cast<int16_t>(100 * i + 50), static_cast<int16_t>(-30 * i)};
  }
  for (size_t n = 1; n < pts.size(); ++n) {
    const PointQ q = pts[n];
    int32_t expected = std::numeric_limits<int32_t>::max();
    for (size_t i = 0; i < n; ++i) {
      const int32_t dx = pts[i].x - q.x, dy = pts[i].y - q.y;
      expected = std::min(expected, dx * dx + dy * dy);
    }
    ASSERT_GT(expected, 0);
    EXPECT_EQ(NearestSquaredSmall(q, std::span<const PointQ>(pts.data(), n)), expected) << n;
  }
}

}  // namespace
}  // namespace handdb
