#include "query/point_buckets.h"

#include <gtest/gtest.h>

#include <limits>
#include <random>
#include <vector>

#include "format/shard_testing.h"
#include "query/chamfer.h"
#include "query/kdtree.h"
#include "query/search_testing.h"

namespace handdb {
namespace {

using testing::RandomPoints;

int32_t BruteNearest(PointQ q, const std::vector<PointQ>& set) {
  int64_t best = std::numeric_limits<int64_t>::max();
  for (const PointQ& p : set) best = std::min(best, SquaredDistanceQ(p, q));
  return static_cast<int32_t>(best);
}

// Every answer equals the brute-force nearest squared distance: sets of 1 to 800 points, dense
// and sparse, clustered on hand-like outlines; probes near the set, far away (beyond the 5 x 5
// cells, so the full scan answers), on cell borders and off the coarse grid.
TEST(PointBuckets, NearestEqualsBruteForce) {
  std::mt19937 rng(3);
  PointBuckets buckets;
  for (int i = 0; i < 120; ++i) {
    std::vector<PointQ> set;
    if (i % 3 == 0) {
      set = testing::SyntheticEdgeSet(static_cast<uint32_t>(i), 50 + 5 * i);
    } else {
      set = RandomPoints(&rng, 1 + (i * 37) % 800, i % 2 ? 160 * 16 : 20 * 16);
    }
    ASSERT_TRUE(buckets.Build(set));
    ASSERT_EQ(buckets.size(), set.size());
    auto probes = RandomPoints(&rng, 300, 250 * 16);  // some off the grid (+-172 px)
    for (const PointQ& p : RandomPoints(&rng, 300, 170 * 16)) probes.push_back(p);
    for (int c = -3; c <= 3; ++c) {  // on cell borders (multiples of 8 px from -172 px)
      probes.push_back({static_cast<int16_t>(-2752 + 128 * (21 + c)), 5});
      probes.push_back({7, static_cast<int16_t>(-2752 + 128 * (21 + c))});
    }
    for (const PointQ& q : probes) {
      ASSERT_EQ(buckets.NearestSquared(q), BruteNearest(q, set))
          << "set " << i << " probe " << q.x << "," << q.y;
    }
  }
}

// The sums equal the kd-tree's bit for bit (same exact squared distances, same order), and stop
// at the same point.
TEST(PointBuckets, SumsEqualTheKdTreeBitForBit) {
  std::mt19937 rng(4);
  PointBuckets buckets;
  for (int i = 0; i < 20; ++i) {
    const auto set = RandomPoints(&rng, 50 + 30 * i, 120 * 16);
    const auto from = RandomPoints(&rng, 40 + 20 * i, 140 * 16);
    ASSERT_TRUE(buckets.Build(set));
    const KdTree tree(set, KdTreeBackend::kNanoflann);
    const double inf = std::numeric_limits<double>::infinity();
    EXPECT_EQ(buckets.SumNearestDistances(from, inf), tree.SumNearestDistances(from, inf));
    bool stopped_b = false;
    bool stopped_t = false;
    const double stop = 0.3 * tree.SumNearestDistances(from, inf);
    EXPECT_EQ(buckets.SumNearestDistances(from, stop, &stopped_b),
              tree.SumNearestDistances(from, stop, &stopped_t));
    EXPECT_TRUE(stopped_b);
    EXPECT_TRUE(stopped_t);
  }
}

// A set with a point off the coarse grid (or beyond the scans' coordinate range) is refused, so
// the caller falls back to a kd-tree.
TEST(PointBuckets, RefusesPointsOffTheGrid) {
  PointBuckets buckets;
  EXPECT_FALSE(buckets.Build(std::vector<PointQ>{{0, 0}, {static_cast<int16_t>(2752), 0}}));
  EXPECT_FALSE(buckets.usable());
  EXPECT_FALSE(buckets.Build(std::vector<PointQ>{{0, static_cast<int16_t>(-2753)}}));
  EXPECT_TRUE(buckets.Build(std::vector<PointQ>{{static_cast<int16_t>(2751), -2752}}));
  EXPECT_TRUE(buckets.usable());
  EXPECT_EQ(buckets.NearestSquared({static_cast<int16_t>(2751), -2752}), 0);
}

}  // namespace
}  // namespace handdb
