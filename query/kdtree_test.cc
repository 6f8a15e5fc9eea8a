#include "query/kdtree.h"

#include <gtest/gtest.h>

#include <limits>
#include <random>
#include <thread>
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

int64_t BruteNearest(std::span<const PointQ> pts, PointQ q) {
  int64_t best = std::numeric_limits<int64_t>::max();
  for (const auto& p : pts) best = std::min(best, SquaredDistanceQ(p, q));
  return best;
}

class KdTreeBackends : public ::testing::TestWithParam<KdTreeBackend> {};

TEST_P(KdTreeBackends, NearestIsExact) {
  // Coordinates up to +-170 px (the normalised frame), including many exact ties on a coarse grid.
  for (int range : {170 * 16, 40}) {
    const auto pts = RandomPoints(700, range, 1);
    const KdTree tree(pts, GetParam());
    const auto queries = RandomPoints(2000, range + 100, 2);
    for (const PointQ& q : queries) {
      uint32_t index = 0;
      const int64_t sq = tree.NearestSquared(q, &index);
      ASSERT_EQ(sq, BruteNearest(pts, q));
      ASSERT_EQ(sq, SquaredDistanceQ(q, pts[index]));
    }
  }
}

TEST_P(KdTreeBackends, SumAndEarlyStop) {
  const auto pts = RandomPoints(300, 2000, 3);
  const auto queries = RandomPoints(500, 2000, 4);
  const KdTree tree(pts, GetParam());
  double expected = 0;
  for (const PointQ& q : queries) expected += std::sqrt(double(BruteNearest(pts, q))) / 16.0;
  bool stopped = true;
  EXPECT_EQ(tree.SumNearestDistances(queries, std::numeric_limits<double>::infinity(), &stopped),
            expected);
  EXPECT_FALSE(stopped);
  const double partial = tree.SumNearestDistances(queries, expected / 2, &stopped);
  EXPECT_TRUE(stopped);
  EXPECT_GT(partial, expected / 2);
  EXPECT_LE(partial, expected);
  // Stopping happens only strictly above the limit.
  EXPECT_EQ(tree.SumNearestDistances(queries, expected, &stopped), expected);
  EXPECT_FALSE(stopped);
}

TEST_P(KdTreeBackends, ConstQueriesFromManyThreads) {
  const auto pts = RandomPoints(1000, 2500, 5);
  const auto queries = RandomPoints(4000, 2500, 6);
  const KdTree tree(pts, GetParam());
  const double expected = tree.SumNearestDistances(queries, 1e300);
  std::vector<double> got(4);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] { got[t] = tree.SumNearestDistances(queries, 1e300); });
  }
  for (auto& t : threads) t.join();
  for (double g : got) EXPECT_EQ(g, expected);
}

TEST_P(KdTreeBackends, SinglePointAndDuplicates) {
  const std::vector<PointQ> one = {{5, -7}};
  const KdTree t1(one, GetParam());
  EXPECT_EQ(t1.NearestSquared({5, -7}), 0);
  EXPECT_EQ(t1.NearestSquared({8, -3}), 25);
  const std::vector<PointQ> dup(50, PointQ{1, 1});
  const KdTree t2(dup, GetParam());
  EXPECT_EQ(t2.NearestSquared({4, 5}), 25);
}

INSTANTIATE_TEST_SUITE_P(All,
                         KdTreeBackends,
                         ::testing::Values(KdTreeBackend::kNanoflann, KdTreeBackend::kPcl),
                         [](const auto& info) {
                           return std::string(KdTreeBackendName(info.param));
                         });

TEST(KdTree, BackendsAgreeExactly) {
  const auto pts = RandomPoints(800, 170 * 16, 7);
  const auto queries = RandomPoints(3000, 170 * 16, 8);
  const KdTree a(pts, KdTreeBackend::kNanoflann);
  const KdTree b(pts, KdTreeBackend::kPcl);
  for (const PointQ& q : queries) ASSERT_EQ(a.NearestSquared(q), b.NearestSquared(q));
  EXPECT_EQ(a.SumNearestDistances(queries, 1e300), b.SumNearestDistances(queries, 1e300));
}

TEST(KdTree, EmptyPointSetIsAProgrammingError) {
  const std::vector<PointQ> none;
  EXPECT_THROW(KdTree(none, KdTreeBackend::kNanoflann), std::logic_error);
}

TEST(KdTree, ParseBackend) {
  EXPECT_EQ(*ParseKdTreeBackend("pcl"), KdTreeBackend::kPcl);
  EXPECT_EQ(*ParseKdTreeBackend("nanoflann"), KdTreeBackend::kNanoflann);
  const auto bad = ParseKdTreeBackend("flann");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace handdb
