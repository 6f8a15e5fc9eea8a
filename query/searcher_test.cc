#include "query/searcher.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <random>
#include <vector>

#include "base/testing.h"
#include "format/manifest.h"
#include "format/shard_layout.h"
#include "format/shard_testing.h"
#include "format/shard_writer.h"
#include "query/search_run.h"
#include "query/search_testing.h"

namespace handdb {
namespace {

using testing::RolledView;
using testing::SyntheticDatabase;

constexpr uint32_t kViews = 36;
constexpr uint32_t kRolls = 16;
constexpr size_t kPoints = 120;

std::shared_ptr<const Database> TestDatabase() {
  static const auto db = std::make_shared<const Database>(
      SyntheticDatabase(kViews, kPoints, kRolls, /*views_per_shape=*/6));
  return db;
}

// The same views with their points sorted by (y, x), as the converter writes them
// (edges/view_conversion.h): the linear scans then read windows of rows instead of buckets.
std::shared_ptr<const Database> SortedTestDatabase() {
  static const auto db = [] {
    std::vector<ViewLabel> labels;
    std::vector<std::vector<PointQ>> points;
    const Database& unsorted = *TestDatabase();
    for (view_id_t v = 0; v < unsorted.num_views(); ++v) {
      labels.push_back(unsorted.label(v));
      const auto p = unsorted.points(v);
      points.emplace_back(p.begin(), p.end());
      std::sort(points.back().begin(), points.back().end(), [](PointQ a, PointQ b) {
        return a.y != b.y ? a.y < b.y : a.x < b.x;
      });
    }
    return std::make_shared<const Database>(
        Database::FromMemory(std::move(labels), std::move(points), kRolls));
  }();
  return db;
}

SearchOptions Options(int k = 5, int threads = 2) {
  SearchOptions o;
  o.top_k = k;
  o.num_threads = threads;
  return o;
}

std::vector<Point2f> Transform(std::vector<Point2f> pts,
                               float angle,
                               float dx,
                               float dy,
                               double keep_fraction,
                               uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Point2f> out;
  const float c = std::cos(angle);
  const float s = std::sin(angle);
  for (const auto& p : pts) {
    if (u(rng) > keep_fraction) continue;
    out.push_back({c * p.x - s * p.y + dx, s * p.x + c * p.y + dy});
  }
  return out;
}

void ExpectSameResults(const std::vector<Match>& a, const std::vector<Match>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].view_id, b[i].view_id) << "rank " << i;
    EXPECT_EQ(a[i].roll, b[i].roll) << "rank " << i;
    EXPECT_EQ(a[i].distance, b[i].distance) << "rank " << i;
    EXPECT_EQ(a[i].a, b[i].a) << "rank " << i;
    EXPECT_EQ(a[i].b, b[i].b) << "rank " << i;
    EXPECT_EQ(a[i].hand, b[i].hand) << "rank " << i;
  }
}

// Searches `q` with `pruned` and by brute force (the same options otherwise), expects identical
// results and returns the pruned search's.
std::vector<Match> SearchBothWays(const Searcher& searcher,
                                  const std::vector<Point2f>& q,
                                  const SearchOptions& pruned) {
  SearchOptions brute = pruned;
  brute.brute_force = true;
  auto a = searcher.Search(q, pruned);
  auto b = searcher.Search(q, brute);
  EXPECT_TRUE(a.ok() && b.ok());
  if (!a.ok() || !b.ok()) return {};
  ExpectSameResults(*a, *b);
  return *a;
}

// A random view of the test database at a random roll, turned by up to 0.3 rad, shifted by up to
// 3 px and thinned to 60-100% of its points (`seed` picks the points kept).
std::vector<Point2f> NearViewQuery(std::mt19937& rng, uint32_t seed) {
  std::uniform_int_distribution<uint32_t> view(0, kViews - 1);
  std::uniform_int_distribution<uint32_t> roll(0, kRolls - 1);
  std::uniform_real_distribution<float> u(-1, 1);
  return Transform(RolledView(*TestDatabase(), view(rng), roll(rng)),
                   0.3f * u(rng),
                   3 * u(rng),
                   3 * u(rng),
                   0.6 + 0.4 * (u(rng) + 1) / 2,
                   seed);
}

std::vector<Point2f> Mirrored(std::vector<Point2f> pts) {
  for (Point2f& p : pts) p.x = -p.x;
  return pts;
}

TEST(SearchOptions, Check) {
  EXPECT_TRUE(SearchOptions{}.Check());
  SearchOptions o;
  o.top_k = 0;
  EXPECT_FALSE(o.Check());
  o = {};
  o.num_threads = 0;
  EXPECT_FALSE(o.Check());
  o = {};
  o.dt_cell_px = 0.3f;
  EXPECT_FALSE(o.Check());
  o = {};
  o.max_per_shape = -1;
  EXPECT_FALSE(o.Check());
}

TEST(Searcher, ViewQueriedWithItsOwnEdgesIsRankOneAtDistanceZero) {
  const Searcher searcher(TestDatabase());
  for (view_id_t v : {0u, 7u, 35u}) {
    for (roll_id_t r : {0u, 1u, 5u, 12u}) {
      SearchStats stats;
      auto res = searcher.Search(RolledView(*TestDatabase(), v, r), Options(), &stats);
      ASSERT_TRUE(res.ok()) << res.status().ToString();
      ASSERT_FALSE(res->empty());
      EXPECT_EQ((*res)[0].view_id, v);
      EXPECT_EQ((*res)[0].roll, r);
      EXPECT_EQ((*res)[0].distance, 0.0);
      EXPECT_GT((*res)[1].distance, 0.0);
      // Pruning did its job: far fewer exact evaluations than virtual views.
      EXPECT_LT(stats.refined, stats.virtual_views / 2);
      // The label is the rolled one.
      const ViewLabel canonical = TestDatabase()->label(v);
      EXPECT_NEAR((*res)[0].label.camera_roll,
                  std::remainder(RollAngle(r, kRolls), static_cast<float>(2 * M_PI)),
                  1e-5);
      EXPECT_EQ((*res)[0].label.joint_angles, canonical.joint_angles);
      EXPECT_EQ((*res)[0].shape_name, "shape" + std::to_string(canonical.shape_id));
    }
  }
}

// `--top 100000`, `--bruteforce` and big photo queries can run for minutes; they must not do so
// without a progress line. A search that has run long enough (progress_since in the past) reports
// every phase on stderr with its final count; a fast one prints nothing; the result is the same.
TEST(Searcher, LongSearchesShowProgressOnStderrFastOnesNothing) {
  const Searcher searcher(TestDatabase());
  // Turned, shifted, thinned and cluttered, so that the refine step has pairs left to visit.
  auto query = Transform(RolledView(*TestDatabase(), 7, 3), 0.2f, 3, -2, 0.7, 5);
  std::mt19937 rng(6);
  std::uniform_real_distribution<float> clutter(-100, 100);
  for (int i = 0; i < 200; ++i) query.push_back({clutter(rng), clutter(rng)});
  SearchOptions options = Options();
  options.hand = Hand::kEither;
  options.top_k = 40;  // more pairs near the k-th best than the bounds step scores
  auto quiet = searcher.Search(query, options);
  ASSERT_TRUE(quiet.ok());

  options.progress = true;
  ::testing::internal::CaptureStderr();
  auto fast = searcher.Search(query, options);
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");  // stderr is not a terminal: 5 s
  ASSERT_TRUE(fast.ok());

  options.progress_since = std::chrono::steady_clock::now() - std::chrono::minutes(1);
  ::testing::internal::CaptureStderr();
  auto slow = searcher.Search(query, options);
  const std::string log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(slow.ok());
  // Both hands are one search: 2 x kRolls (hand, roll) slots.
  for (const char* line : {"query bounds (both hands) ", "query refine (both hands) "}) {
    EXPECT_NE(log.find(line), std::string::npos) << line << " missing from:\n" << log;
  }
  const std::string rolls = std::to_string(2 * kRolls) + "/" + std::to_string(2 * kRolls);
  EXPECT_NE(log.find(rolls + " 100.0%  "), std::string::npos) << log;
  EXPECT_EQ(log.find("\r"), std::string::npos);  // not a terminal: whole lines only

  options.brute_force = true;
  options.hand = Hand::kRight;
  ::testing::internal::CaptureStderr();
  auto brute = searcher.Search(query, options);
  const std::string brute_log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(brute.ok());
  const uint64_t pairs = TestDatabase()->num_virtual_views();
  EXPECT_NE(brute_log.find("query brute force " + std::to_string(pairs) + "/" +
                           std::to_string(pairs) + " 100.0%  "),
            std::string::npos)
      << brute_log;
  ASSERT_EQ(slow->size(), quiet->size());
  for (size_t i = 0; i < quiet->size(); ++i) {
    EXPECT_EQ((*slow)[i].view_id, (*quiet)[i].view_id);
    EXPECT_EQ((*slow)[i].distance, (*quiet)[i].distance);
  }
}

TEST(Searcher, SmallRotationsShiftsAndDroppedPointsKeepTopOne) {
  const Searcher searcher(TestDatabase());
  const float step = static_cast<float>(2 * M_PI / kRolls);
  uint32_t seed = 0;
  for (view_id_t v : {3u, 11u, 20u, 29u}) {
    for (roll_id_t r : {0u, 9u}) {
      const auto base = RolledView(*TestDatabase(), v, r);
      const std::vector<std::vector<Point2f>> variants = {
          Transform(base, 0.15f * step, 0, 0, 1.0, ++seed),        // small rotation
          Transform(base, 0, 2.0f, -1.5f, 1.0, ++seed),            // shift
          Transform(base, 0, 0, 0, 0.7, ++seed),                   // 30% of the points dropped
          Transform(base, -0.1f * step, -1.0f, 1.0f, 0.8, ++seed)  // all three
      };
      for (const auto& q : variants) {
        auto res = searcher.Search(q, Options(3));
        ASSERT_TRUE(res.ok());
        EXPECT_EQ((*res)[0].view_id, v);
        EXPECT_EQ((*res)[0].roll, r);
        EXPECT_GT((*res)[0].distance, 0.0);
      }
    }
  }
}

// >= 50 random queries: pruned == brute force (views, order, distances), for both backends and
// any thread count.
// With either coarse field for the A bound (the centre field by default, the box field that
// `handdb query` uses for its single query).
TEST(Searcher, PrunedEqualsBruteForce) {
  for (const auto& [sorted, kind] : {std::pair{false, FieldKind::kCentre},
                                     std::pair{true, FieldKind::kCentre},
                                     std::pair{true, FieldKind::kBox}}) {
    Searcher searcher(sorted ? SortedTestDatabase() : TestDatabase());
    searcher.SetExactFieldKind(kind);
    std::mt19937 rng(42);
    std::uniform_int_distribution<uint32_t> view(0, kViews - 1);
    std::uniform_int_distribution<uint32_t> roll(0, kRolls - 1);
    std::uniform_real_distribution<float> u(-1, 1);
    for (int i = 0; i < (kind == FieldKind::kCentre ? 60 : 24); ++i) {
      std::vector<Point2f> q;
      if (i % 4 == 3) {
        // A shape unlike any view: an unrelated synthetic set.
        RollPoints(testing::SyntheticEdgeSet(1000 + i, 100), 0.0f, &q);
      } else {
        q = Transform(RolledView(*TestDatabase(), view(rng), roll(rng)),
                      0.3f * u(rng),
                      4 * u(rng),
                      4 * u(rng),
                      0.5 + 0.5 * (u(rng) + 1) / 2,
                      i);
      }
      SearchOptions pruned = Options(1 + i % 8, 1 + i % 3);
      pruned.kdtree = i % 2 ? KdTreeBackend::kPcl : KdTreeBackend::kNanoflann;
      pruned.dt_cell_px = i % 5 == 0 ? 0.5f : 1.0f;
      pruned.coarse_bound = i % 3 != 1;
      SearchOptions brute = pruned;
      brute.brute_force = true;
      brute.num_threads = 2;
      brute.kdtree = KdTreeBackend::kNanoflann;
      auto a = searcher.Search(q, pruned);
      auto b = searcher.Search(q, brute);
      ASSERT_TRUE(a.ok() && b.ok());
      ExpectSameResults(*a, *b);
      for (const Match& m : *a) {
        EXPECT_LE(m.lower_bound, m.distance + 1e-9);
        if (!pruned.coarse_bound) {
          EXPECT_LE(m.lower_bound, m.b + 1e-9);
        }
        EXPECT_DOUBLE_EQ(m.distance, m.a + m.b);
      }
    }
  }
}

// A per-shape limit m keeps each shape's m best pairs, then the k best of those: the pruned
// search (which also prunes each pair on its own shape's m-th best) equals brute force under the
// same limit, and both equal the full ranking with each shape's pairs after its m-th dropped.
// The test database has 6 shapes of 6 views, so k up to 8 with m = 1 asks for more shapes than
// some queries' neighbourhoods hold.
TEST(Searcher, PerShapeLimitEqualsTheFullRankingFiltered) {
  for (const bool sorted : {false, true}) {
    const Searcher searcher(sorted ? SortedTestDatabase() : TestDatabase());
    std::mt19937 rng(11);
    for (int i = 0; i < 24; ++i) {
      std::vector<Point2f> q = NearViewQuery(rng, 300 + i);
      if (i % 4 == 1) q = Mirrored(q);
      SearchOptions pruned = Options(1 + i % 8, 1 + i % 2);
      pruned.max_per_shape = 1 + i % 3 / 2;  // 1, 1, 2, ...
      pruned.hand = i % 2 ? Hand::kEither : Hand::kRight;
      pruned.coarse_bound = i % 5 != 4;
      const std::vector<Match> a = SearchBothWays(searcher, q, pruned);

      SearchOptions all = pruned;
      all.max_per_shape = 0;
      all.brute_force = true;
      all.top_k = static_cast<int>(kViews * kRolls * 2);
      auto full = searcher.Search(q, all);
      ASSERT_TRUE(full.ok());
      std::vector<Match> expected;
      std::map<shape_id_t, int> per_shape;
      for (const Match& m : *full) {
        if (expected.size() == static_cast<size_t>(pruned.top_k)) break;
        if (per_shape[m.label.shape_id]++ < pruned.max_per_shape) expected.push_back(m);
      }
      ExpectSameResults(a, expected);
      std::map<shape_id_t, int> count;
      for (const Match& m : a) EXPECT_LE(++count[m.label.shape_id], pruned.max_per_shape);
    }
  }
}

// Rolls r and r + R/2 share one distance grid when R is even (the second read at -p), and the
// mirrored query's rolls read the right hand's grids (at (-x, y) and (x, -y)); odd R and R = 1, 2
// take the other paths. Pruned equals brute force for each hand setting, and every bound is below
// its D_c.
// The fine bounds' grids: every slot read from exactly one grid, R/4 grids when R is a multiple
// of 4 (roll r + R/4 turned), R/2 when R is even, R otherwise; a base is never turned or flipped.
TEST(Searcher, FineGridGroupsCoverEverySlotOnce) {
  for (const uint32_t rolls : {1u, 2u, 3u, 4u, 6u, 12u, 48u}) {
    for (const size_t slots : {size_t{rolls}, 2 * size_t{rolls}}) {
      const auto groups = search_internal::MakeFineGridGroups(slots, rolls);
      const size_t expected = rolls % 4 == 0 ? rolls / 4 : (rolls % 2 == 0 ? rolls / 2 : rolls);
      EXPECT_EQ(groups.size(), expected) << rolls << " rolls, " << slots << " slots";
      std::vector<int> seen(slots, 0);
      for (const auto& group : groups) {
        ASSERT_FALSE(group.empty());
        EXPECT_EQ(group[0].flip, GridFlip::kNone);
        EXPECT_FALSE(group[0].turned);
        for (const auto& m : group) {
          ASSERT_LT(m.slot, slots);
          ++seen[m.slot];
        }
      }
      EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), static_cast<ptrdiff_t>(slots))
          << rolls << " rolls, " << slots << " slots";
    }
  }
}

TEST(Searcher, PrunedEqualsBruteForceForOddAndTinyRollCounts) {
  for (const uint32_t rolls : {1u, 2u, 3u, 4u, 12u, 15u, 48u}) {
    const auto db = std::make_shared<const Database>(
        SyntheticDatabase(kViews, kPoints, rolls, /*views_per_shape=*/6));
    const Searcher searcher(db);
    std::mt19937 rng(rolls);
    std::uniform_int_distribution<uint32_t> view(0, kViews - 1);
    std::uniform_int_distribution<uint32_t> roll(0, rolls - 1);
    std::uniform_real_distribution<float> u(-1, 1);
    for (int i = 0; i < 12; ++i) {
      const auto q = Transform(
          RolledView(*db, view(rng), roll(rng)), 0.3f * u(rng), 4 * u(rng), 4 * u(rng), 0.8, i);
      SearchOptions options = Options(1 + i % 6, 1 + i % 2);
      options.hand = i % 3 == 0 ? Hand::kEither : (i % 3 == 1 ? Hand::kRight : Hand::kLeft);
      const auto a = SearchBothWays(searcher, q, options);
      ASSERT_FALSE(a.empty());
      for (const Match& m : a) EXPECT_LE(m.lower_bound, m.distance + 1e-9) << rolls;
    }
  }
}

TEST(Searcher, BackendsAndThreadCountsGiveIdenticalResults) {
  const Searcher searcher(TestDatabase());
  const auto q = Transform(RolledView(*TestDatabase(), 17, 3), 0.05f, 1, 1, 0.9, 7);
  SearchOptions base = Options(10, 1);
  auto ref = searcher.Search(q, base);
  ASSERT_TRUE(ref.ok());
  for (int threads : {1, 2, 4}) {
    for (KdTreeBackend backend : {KdTreeBackend::kNanoflann, KdTreeBackend::kPcl}) {
      SearchOptions o = base;
      o.num_threads = threads;
      o.kdtree = backend;
      auto got = searcher.Search(q, o);
      ASSERT_TRUE(got.ok());
      ExpectSameResults(*ref, *got);
    }
  }
}

TEST(Searcher, TopKLargerThanTheDatabaseReturnsEverything) {
  const auto db = std::make_shared<const Database>(SyntheticDatabase(3, 50, 4));
  const Searcher searcher(db);
  auto res = searcher.Search(RolledView(*db, 1, 2), Options(100));
  ASSERT_TRUE(res.ok());
  EXPECT_EQ(res->size(), 12u);
  for (size_t i = 1; i < res->size(); ++i) EXPECT_LE((*res)[i - 1].distance, (*res)[i].distance);
}

TEST(Searcher, ManyThreadsQueryOneSearcher) {
  const Searcher searcher(TestDatabase());
  std::vector<std::vector<Match>> got(4);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      got[t] = *searcher.Search(RolledView(*TestDatabase(), 5 + t, t), Options(4, 1));
    });
  }
  for (auto& t : threads) t.join();
  for (int t = 0; t < 4; ++t) {
    EXPECT_EQ(got[t][0].view_id, static_cast<view_id_t>(5 + t));
    EXPECT_EQ(got[t][0].distance, 0.0);
  }
}

TEST(Searcher, BadInputs) {
  const Searcher searcher(TestDatabase());
  const std::vector<Point2f> empty;
  auto res = searcher.Search(empty, Options());
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.status().code(), StatusCode::kInvalidArgument);
  const std::vector<Point2f> nan = {{0, 0}, {std::nanf(""), 1}};
  res = searcher.Search(nan, Options());
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.status().code(), StatusCode::kInvalidArgument);
  const std::vector<Point2f> far = {{0, 0}, {1e6f, 1}};
  EXPECT_FALSE(searcher.Search(far, Options()).ok());
  SearchOptions bad = Options();
  bad.top_k = -3;
  res = searcher.Search(RolledView(*TestDatabase(), 0, 0), bad);
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.status().code(), StatusCode::kInvalidArgument);
}

TEST(Hand, NamesRoundTripAndMirrorLabelIsItsOwnInverse) {
  for (Hand h : {Hand::kRight, Hand::kLeft, Hand::kEither}) EXPECT_EQ(*ParseHand(HandName(h)), h);
  EXPECT_FALSE(ParseHand("both").ok());
  ViewLabel l = TestDatabase()->label(4);
  l.keypoints[3] = {12.5f, -7.25f, 3.0f};
  l.view_direction = {0.6f, 0.8f, 0.0f};
  l.view_phi = std::atan2(0.8f, 0.6f);
  l.camera_roll = 0.5f;
  const ViewLabel m = MirrorLabel(l);
  EXPECT_EQ(m.keypoints[3][0], -12.5f);
  EXPECT_EQ(m.keypoints[3][1], -7.25f);
  EXPECT_EQ(m.keypoints[3][2], 3.0f);
  EXPECT_EQ(m.camera_roll, -0.5f);
  EXPECT_EQ(m.view_direction[1], -0.8f);
  EXPECT_FLOAT_EQ(m.view_phi, std::atan2(m.view_direction[1], m.view_direction[0]));
  EXPECT_EQ(m.joint_angles, l.joint_angles);
  const ViewLabel back = MirrorLabel(m);
  EXPECT_EQ(back.keypoints, l.keypoints);
  EXPECT_EQ(back.camera_roll, l.camera_roll);
  EXPECT_EQ(back.view_direction, l.view_direction);
}

// A left hand is a mirrored right hand: a mirrored (rolled) view comes back at rank 1, D_c exactly
// 0, as a left-hand match whose keypoints are the view's mirrored into the query's frame; the
// unmirrored view is still a right-hand match under every option but kLeft.
TEST(Searcher, MirroredViewIsFoundAsALeftHand) {
  const Searcher searcher(TestDatabase());
  for (view_id_t v : {0u, 7u, 35u}) {
    for (roll_id_t r : {0u, 5u, 11u}) {
      const auto right = RolledView(*TestDatabase(), v, r);
      const auto left = Mirrored(right);
      const ViewLabel rolled = RollLabel(TestDatabase()->label(v), RollAngle(r, kRolls));
      for (Hand h : {Hand::kLeft, Hand::kEither}) {
        SearchOptions o = Options();
        o.hand = h;
        SearchStats stats;
        auto res = searcher.Search(left, o, &stats);
        ASSERT_TRUE(res.ok());
        EXPECT_EQ(stats.searches, h == Hand::kEither ? 2u : 1u);
        EXPECT_EQ((*res)[0].view_id, v);
        EXPECT_EQ((*res)[0].roll, r);
        EXPECT_EQ((*res)[0].distance, 0.0);
        EXPECT_EQ((*res)[0].hand, Hand::kLeft);
        for (int k = 0; k < kNumKeypoints; ++k) {
          EXPECT_EQ((*res)[0].label.keypoints[k][0], -rolled.keypoints[k][0]);
          EXPECT_EQ((*res)[0].label.keypoints[k][1], rolled.keypoints[k][1]);
        }
        EXPECT_EQ((*res)[0].label.camera_roll, -rolled.camera_roll);
      }
      for (Hand h : {Hand::kRight, Hand::kEither}) {
        SearchOptions o = Options();
        o.hand = h;
        auto res = searcher.Search(right, o);
        ASSERT_TRUE(res.ok());
        EXPECT_EQ((*res)[0].view_id, v);
        EXPECT_EQ((*res)[0].roll, r);
        EXPECT_EQ((*res)[0].distance, 0.0);
        EXPECT_EQ((*res)[0].hand, Hand::kRight);
        EXPECT_EQ((*res)[0].label.keypoints, rolled.keypoints);
      }
    }
  }
}

// kEither's second (mirrored) search starts from the first one's k-th best; the merged top-k
// must still equal brute force over both hands, and kLeft must equal brute force on the mirror.
TEST(Searcher, EitherHandPrunedEqualsBruteForce) {
  for (const bool sorted : {false, true}) {
    const Searcher searcher(sorted ? SortedTestDatabase() : TestDatabase());
    std::mt19937 rng(7);
    int left_won = 0;
    for (int i = 0; i < 24; ++i) {
      std::vector<Point2f> q = NearViewQuery(rng, 100 + i);
      if (i % 2) q = Mirrored(q);
      SearchOptions pruned = Options(1 + i % 6, 1 + i % 2);
      pruned.hand = i % 3 == 2 ? Hand::kLeft : Hand::kEither;
      const auto a = SearchBothWays(searcher, q, pruned);
      ASSERT_FALSE(a.empty());
      if (a[0].hand == Hand::kLeft) ++left_won;
    }
    EXPECT_GT(left_won, 4);  // both hands won somewhere, so the merge was exercised
    EXPECT_LT(left_won, 20);
  }
}

// A subset search (a tracker's neighbourhood) is the brute-force ranking of every pair, filtered
// to the subset, cut at k: for random subsets of either hand, with and without a per-shape limit.
TEST(Searcher, SubsetSearchEqualsBruteForceOverTheSubset) {
  const Searcher searcher(SortedTestDatabase());
  std::mt19937 rng(11);
  std::uniform_int_distribution<uint32_t> view(0, kViews - 1);
  std::uniform_int_distribution<uint32_t> roll(0, kRolls - 1);
  int outside_best = 0;
  for (int i = 0; i < 24; ++i) {
    std::vector<Point2f> q = NearViewQuery(rng, 300 + i);
    if (i % 3 == 1) q = Mirrored(q);
    std::vector<SearchPair> subset;
    const size_t n = 1 + (i * 37) % 200;
    for (size_t j = 0; j < n; ++j) {
      subset.push_back({view(rng), roll(rng), j % 2 ? Hand::kLeft : Hand::kRight});
    }
    subset.push_back(subset.front());  // repeats are allowed
    SearchOptions options = Options(1 + i % 7, 1 + i % 2);
    options.hand = i % 4 == 3 ? Hand::kRight : Hand::kEither;
    options.max_per_shape = i % 5 == 2 ? 1 : 0;
    SearchOptions all = options;
    all.top_k = static_cast<int>(2 * kViews * kRolls);
    all.max_per_shape = 0;
    all.brute_force = true;
    auto every = searcher.Search(q, all);
    ASSERT_TRUE(every.ok());
    auto in_subset = [&](const Match& m) {
      return std::any_of(subset.begin(), subset.end(), [&](const SearchPair& p) {
        return p.view == m.view_id && p.roll == m.roll && p.hand == m.hand;
      });
    };
    std::vector<Match> expected;
    std::map<uint32_t, int> per_shape;
    for (const Match& m : *every) {
      if (!in_subset(m)) continue;
      const uint32_t shape = TestDatabase()->label(m.view_id).shape_id;
      if (options.max_per_shape > 0 && per_shape[shape]++ >= options.max_per_shape) continue;
      if (expected.size() < static_cast<size_t>(options.top_k)) expected.push_back(m);
    }
    if (!in_subset(every->front())) ++outside_best;
    options.subset = subset;
    SearchStats stats;
    auto got = searcher.Search(q, options, &stats);
    ASSERT_TRUE(got.ok());
    ExpectSameResults(*got, expected);
    EXPECT_GT(stats.candidates, 0u);
    EXPECT_LE(stats.bounded, subset.size());
  }
  EXPECT_GT(outside_best, 10);  // the subset did restrict the answer
}

// A subset without a pair of the hand searched (or inside the database) finds nothing.
TEST(Searcher, SubsetOfAnotherHandFindsNothing) {
  const Searcher searcher(TestDatabase());
  std::mt19937 rng(5);
  const std::vector<Point2f> q = NearViewQuery(rng, 9);
  const std::vector<SearchPair> subset = {{1, 2, Hand::kLeft}, {kViews + 3, 0, Hand::kRight}};
  SearchOptions options = Options(3);
  options.subset = subset;
  auto got = searcher.Search(q, options);
  ASSERT_TRUE(got.ok());
  EXPECT_TRUE(got->empty());
}

TEST(Searcher, MissingDatabaseDirectory) {
  const auto res = Searcher::Open("/nonexistent/handdb-db");
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.status().code(), StatusCode::kNotFound);
}

// A database directory of the sorted test views in two shards, plain (v1.1) or coded (v1.2).
std::filesystem::path WriteTestDatabase(const std::string& name, bool coded) {
  const std::filesystem::path dir = ::handdb::testing::TempDir(name);
  const Database& src = *SortedTestDatabase();
  Manifest m;
  m.tool_version = "test";
  m.rolls = kRolls;
  for (int shard = 0; shard < 2; ++shard) {
    ShardWriterOptions options;
    options.coded = coded;
    ShardWriter writer;
    const auto path = dir / ("shard-0000" + std::to_string(shard) + ".hdb");
    THROW_CHECK(writer.Open(path, options).ok());
    for (view_id_t v = shard * kViews / 2; v < (shard + 1) * kViews / 2; ++v) {
      THROW_CHECK(writer.AddView(src.label(v), src.points(v)).ok());
    }
    auto summary = writer.Finish();
    THROW_CHECK(summary.ok());
    m.AddShard(*summary);
  }
  THROW_CHECK(WriteManifest(dir, m).ok());
  return dir;
}

TEST(Searcher, CodedShardsSearchExactlyLikePlainOnes) {
  auto plain = Database::Open(WriteTestDatabase("coded_search_plain", false));
  auto coded = Database::Open(WriteTestDatabase("coded_search_coded", true));
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  ASSERT_TRUE(coded.ok()) << coded.status().ToString();
  EXPECT_FALSE(plain->coded());
  EXPECT_TRUE(coded->coded());
  EXPECT_LT(coded->size_bytes(), plain->size_bytes());
  EXPECT_EQ(coded->num_points(), plain->num_points());
  EXPECT_TRUE(coded->has_coarse_fields());
  EXPECT_EQ(coded->decoded_bytes(), 0u);
  std::vector<PointQ> scratch;
  for (view_id_t v = 0; v < kViews; ++v) {
    const auto a = plain->points(v);
    const auto b = coded->ViewPoints(v, &scratch);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_TRUE(std::equal(a.begin(), a.end(), b.begin(), [](PointQ x, PointQ y) {
      return x.x == y.x && x.y == y.y;
    }));
    EXPECT_EQ(coded->point_count(v), a.size());
  }
  EXPECT_EQ(coded->decoded_bytes(), 0u);  // ViewPoints keeps nothing
  auto plain_db = std::make_shared<const Database>(std::move(plain).value());
  auto coded_db = std::make_shared<const Database>(std::move(coded).value());
  Searcher ps(plain_db);
  Searcher cs(coded_db);
  cs.SetExactFieldKind(FieldKind::kBox);  // reads the decoded fields
  ps.SetExactFieldKind(FieldKind::kBox);
  std::mt19937 rng(7);
  std::uniform_int_distribution<uint32_t> view(0, kViews - 1);
  std::uniform_int_distribution<uint32_t> roll(0, kRolls - 1);
  for (int i = 0; i < 12; ++i) {
    const auto q =
        Transform(RolledView(*plain_db, view(rng), roll(rng)), 0.1f, 1.0f, -1.0f, 0.8, i);
    SearchOptions o = Options(5, 1 + i % 2);
    o.hand = i % 3 == 0 ? Hand::kEither : Hand::kRight;
    o.brute_force = i % 4 == 1;
    auto a = ps.Search(q, o);
    auto b = cs.Search(q, o);
    ASSERT_TRUE(a.ok() && b.ok());
    ExpectSameResults(*a, *b);
  }
  EXPECT_GT(coded_db->decoded_bytes(), 0u);
  EXPECT_EQ(plain_db->decoded_bytes(), 0u);
}

// A coded view damaged past its header: Open reads only a lattice-mode code's header, so it
// succeeds, and a search that decodes the view returns the error instead of crashing.
TEST(Database, ACodedViewDamagedPastItsHeaderIsAnErrorOfTheSearch) {
  const std::filesystem::path dir = ::handdb::testing::TempDir("coded_bad_tail");
  Manifest m;
  m.tool_version = "test";
  m.rolls = 4;
  ShardWriterOptions options;
  options.coded = true;
  ShardWriter writer;
  ASSERT_TRUE(writer.Open(dir / "shard-00000.hdb", options).ok());
  for (uint32_t v = 0; v < 6; ++v) {  // converted-like views: lattice-mode codes
    const ViewLabel label = testing::SyntheticViewLabel(v, 6);
    ASSERT_TRUE(writer.AddView(label, ::handdb::testing::LatticePoints(label, v)).ok());
  }
  auto summary = writer.Finish();
  ASSERT_TRUE(summary.ok());
  m.AddShard(*summary);
  ASSERT_TRUE(WriteManifest(dir, m).ok());
  auto good = Database::Open(dir);
  ASSERT_TRUE(good.ok()) << good.status().ToString();
  const std::vector<Point2f> query = RolledView(*good, 2, 1);

  std::vector<uint8_t> bytes = ::handdb::testing::ReadBytes(dir / "shard-00000.hdb");
  ::handdb::testing::DamageFirstPointCode(&bytes);
  {
    std::ofstream out(dir / "shard-00000.hdb", std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
  }
  auto db = Database::Open(dir);
  ASSERT_TRUE(db.ok()) << db.status().ToString();
  Searcher searcher(std::make_shared<const Database>(std::move(db).value()));
  SearchOptions o = Options(3, 2);
  o.brute_force = true;  // every view is decoded
  auto result = searcher.Search(query, o);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("shard-00000.hdb: offset"), std::string::npos)
      << result.status().ToString();
  EXPECT_NE(result.status().message().find("view 0: point code"), std::string::npos)
      << result.status().ToString();
  EXPECT_NE(result.status().message().find("handdb validate"), std::string::npos);
}

TEST(Database, ACodedViewThatDoesNotDecodeIsAnErrorOfOpen) {
  const std::filesystem::path dir = WriteTestDatabase("coded_bad", true);
  const std::filesystem::path shard = dir / "shard-00001.hdb";
  std::vector<uint8_t> bytes = ::handdb::testing::ReadBytes(shard);
  // The first view's point code begins the point_codes section: make its mode byte unknown.
  const shard::RawHeader h = shard::RawHeader::DecodeFrom(bytes);
  for (uint32_t i = 0; i < h.section_count; ++i) {
    const shard::RawSection sec = shard::RawSection::DecodeFrom(
        bytes.data() + h.section_table_offset + i * h.section_entry_size);
    if (sec.type == shard::kSectionPointCodes) bytes[sec.offset] = 0x7f;
  }
  ASSERT_TRUE(shard::RewriteChecksums(bytes));
  {
    std::ofstream out(shard, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
  }
  auto db = Database::Open(dir);
  ASSERT_FALSE(db.ok());
  EXPECT_NE(db.status().message().find("shard-00001.hdb: offset"), std::string::npos)
      << db.status().ToString();
  EXPECT_NE(db.status().message().find("view 0: point code"), std::string::npos)
      << db.status().ToString();
}

}  // namespace
}  // namespace handdb
