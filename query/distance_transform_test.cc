#include "query/distance_transform.h"

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

double ExactDistancePx(std::span<const PointQ> set, PointQ p) {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& q : set) {
    const double dx = p.x - q.x;
    const double dy = p.y - q.y;
    best = std::min(best, std::sqrt(dx * dx + dy * dy));
  }
  return best / 16.0;
}

TEST(DistanceGridOptions, Check) {
  EXPECT_TRUE(DistanceGridOptions{}.Check());
  EXPECT_TRUE((DistanceGridOptions{0.25f, 170}.Check()));
  EXPECT_FALSE((DistanceGridOptions{0.3f, 170}.Check()));
  EXPECT_FALSE((DistanceGridOptions{2.0f, 170}.Check()));
  EXPECT_FALSE((DistanceGridOptions{1.0f, -1}.Check()));
}

TEST(DistanceGrid, NodeValuesAreTheExactEuclideanTransform) {
  // Points exactly on nodes: the DT at every node equals the exact distance to the set.
  std::vector<PointQ> pts;
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> u(-100, 100);
  for (int i = 0; i < 40; ++i)
    pts.push_back({static_cast<int16_t>(u(rng) * 16), static_cast<int16_t>(u(rng) * 16)});
  DistanceGrid grid(DistanceGridOptions{1.0f, 110});
  grid.Build(pts);
  EXPECT_EQ(grid.r_max_px(), 0.0f);
  for (int iy = 0; iy < grid.size(); iy += 7) {
    for (int ix = 0; ix < grid.size(); ix += 5) {
      const PointQ node{static_cast<int16_t>((ix - grid.size() / 2) * 16),
                        static_cast<int16_t>((iy - grid.size() / 2) * 16)};
      // Rounded down to 1/64 px: never above the exact distance, at most 1/64 px below.
      const double exact = ExactDistancePx(pts, node);
      ASSERT_LE(grid.NodeDistance(ix, iy), exact) << ix << "," << iy;
      ASSERT_GT(grid.NodeDistance(ix, iy), exact - 1.0 / 64) << ix << "," << iy;
    }
  }
}

class LowerBound : public ::testing::TestWithParam<float> {};

TEST_P(LowerBound, NeverExceedsTheExactDistanceAndIsTight) {
  const auto set = RandomPoints(600, 150 * 16, 1);
  DistanceGrid grid(DistanceGridOptions{GetParam(), 170});
  grid.Build(set);
  EXPECT_GT(grid.r_max_px(), 0.0f);
  EXPECT_LE(grid.r_max_px(), GetParam() * 0.7072f);
  // Points everywhere, including far outside the grid (the box fallback).
  const auto probes = RandomPoints(20000, 2040 * 16, 2);
  const auto near = RandomPoints(20000, 170 * 16, 3);
  double sum_gap = 0;
  for (const auto* ps : {&probes, &near}) {
    for (const PointQ& p : *ps) {
      const double exact = ExactDistancePx(set, p);
      const double lb = grid.LowerBound(p);
      ASSERT_LE(lb, exact + 1e-5) << p.x << "," << p.y;
      if (ps == &near) sum_gap += exact - lb;
    }
  }
  // Tightness: the mean slack is below the worst case (sqrt(2) cells).
  EXPECT_LT(sum_gap / near.size(), 1.4143 * GetParam());
}

TEST_P(LowerBound, FastSumEqualsPerPointSum) {
  const auto set = RandomPoints(500, 120 * 16, 4);
  DistanceGrid grid(DistanceGridOptions{GetParam(), 170});
  grid.Build(set);
  const auto pts = RandomPoints(999, 160 * 16, 5);
  ASSERT_TRUE(grid.Covers(160 * 16));
  double per_point = 0;
  for (const auto& p : pts) per_point += grid.LowerBound(p);
  const double fast = grid.SumLowerBoundsFast(pts);
  const double mean = fast / pts.size();
  EXPECT_NEAR(mean, per_point / pts.size(), DistanceGrid::MeanLowerBoundMargin(pts.size(), mean));
  EXPECT_EQ(grid.SumLowerBounds(pts), per_point);
}

// Read at F(p), the grid of Q bounds d(p, F(Q)) for every flip F: rolls r and r + R/2 share one
// grid (-Q, kXY), and so do the mirrored query's rolls (Q reflected in x or y). Read turned, at
// T^-1(F(p)), it bounds d(p, F(T(Q))) with T(x, y) = (y, -x): roll r + R/4 shares it too.
TEST_P(LowerBound, FlippedAndTurnedReadsBoundTheMappedSet) {
  const auto set = RandomPoints(600, 150 * 16, 6);
  DistanceGrid grid(DistanceGridOptions{GetParam(), 170});
  grid.Build(set);
  const auto probes = RandomPoints(20000, 2040 * 16, 7);
  const auto near = RandomPoints(20000, 160 * 16, 8);
  ASSERT_TRUE(grid.Covers(160 * 16));
  double plain = 0;
  for (const auto& p : near) plain += grid.LowerBound(p);
  for (const bool turned : {false, true}) {
    for (const GridFlip flip : {GridFlip::kNone, GridFlip::kX, GridFlip::kY, GridFlip::kXY}) {
      if (flip == GridFlip::kNone && !turned) continue;
      SCOPED_TRACE(::testing::Message()
                   << "flip " << static_cast<int>(flip) << " turned " << turned);
      const int sx = flip == GridFlip::kX || flip == GridFlip::kXY ? -1 : 1;
      const int sy = flip == GridFlip::kY || flip == GridFlip::kXY ? -1 : 1;
      std::vector<PointQ> mapped;
      for (const PointQ& q : set) {
        const int tx = turned ? q.y : q.x;
        const int ty = turned ? -q.x : q.y;
        mapped.push_back({static_cast<int16_t>(sx * tx), static_cast<int16_t>(sy * ty)});
      }
      double sum_gap = 0;
      for (const auto* ps : {&probes, &near}) {
        for (const PointQ& p : *ps) {
          const double exact = ExactDistancePx(mapped, p);
          const double lb = grid.LowerBound(p, flip, turned);
          ASSERT_LE(lb, exact + 1e-5) << p.x << "," << p.y;
          if (ps == &near) sum_gap += exact - lb;
        }
      }
      EXPECT_LT(sum_gap / near.size(), 1.4143 * GetParam());
      // The fast and per-point sums agree for these reads too, and differ from plain reads.
      double per_point = 0;
      for (const auto& p : near) per_point += grid.LowerBound(p, flip, turned);
      const double fast = grid.SumLowerBoundsFast(near, flip, turned);
      const double mean = fast / near.size();
      EXPECT_NEAR(
          mean, per_point / near.size(), DistanceGrid::MeanLowerBoundMargin(near.size(), mean));
      EXPECT_EQ(grid.SumLowerBounds(near, flip, turned), per_point);
      EXPECT_NE(per_point, plain);
      // The most negative coordinate maps without overflow (off the grid: the box fallback).
      const PointQ corner{-32768, -32768};
      EXPECT_EQ(grid.LowerBound(corner, flip, turned), grid.LowerBound(corner));
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Cells, LowerBound, ::testing::Values(1.0f, 0.5f, 0.25f));

TEST(DistanceGrid, GrowsToContainFarPoints) {
  const std::vector<PointQ> set = {{0, 0}, {static_cast<int16_t>(400 * 16), 0}};
  DistanceGrid grid(DistanceGridOptions{1.0f, 170});
  grid.Build(set);
  EXPECT_GE(grid.half_extent_px(), 400.0f);
  EXPECT_EQ(grid.LowerBound({static_cast<int16_t>(400 * 16), 0}), 0.0f);
  EXPECT_FALSE(grid.Covers(401 * 16));
}

TEST(DistanceGrid, MatchesBruteForceOnEveryNode) {
  // Small grids with few, clustered and collinear seeds: the cases where the lower envelope of
  // parabolas has ties and replacements.
  for (uint32_t seed = 0; seed < 20; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> u(-12, 12);
    std::vector<PointQ> pts;
    const int count = 1 + static_cast<int>(seed % 7);
    for (int i = 0; i < count; ++i) {
      const int x = seed % 3 == 0 ? 0 : u(rng);  // every third set lies on one column
      pts.push_back({static_cast<int16_t>(x * 16), static_cast<int16_t>(u(rng) * 16)});
    }
    DistanceGrid grid(DistanceGridOptions{1.0f, 14});
    grid.Build(pts);
    for (int iy = 0; iy < grid.size(); ++iy) {
      for (int ix = 0; ix < grid.size(); ++ix) {
        const PointQ node{static_cast<int16_t>((ix - grid.size() / 2) * 16),
                          static_cast<int16_t>((iy - grid.size() / 2) * 16)};
        const double exact = ExactDistancePx(pts, node);
        ASSERT_EQ(grid.NodeDistance(ix, iy), std::floor(exact * 64) / 64)
            << "seed " << seed << " node " << ix << "," << iy;
      }
    }
  }
}

TEST(DistanceGrid, FarPointsCoarsenTheGridInsteadOfGrowingIt) {
  const std::vector<PointQ> set = {{0, 0}, {static_cast<int16_t>(1900 * 16), 0}};
  DistanceGrid grid(DistanceGridOptions{1.0f / 16, 170});
  grid.Build(set);
  EXPECT_LE(grid.size(), 2049);
  EXPECT_EQ(grid.cell_px(), 2.0f);
  const auto probes = RandomPoints(5000, 2000 * 16, 9);
  for (const PointQ& p : probes) ASSERT_LE(grid.LowerBound(p), ExactDistancePx(set, p) + 1e-5);
}

}  // namespace
}  // namespace handdb
