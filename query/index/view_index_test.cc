#include "query/index/view_index.h"

#include <gtest/gtest.h>
#include <xxhash.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "query/chamfer.h"
#include "query/index/embedding.h"
#include "query/search_testing.h"
#include "query/searcher.h"

namespace handdb {
namespace {

using testing::RolledView;
using testing::SyntheticDatabase;

constexpr uint32_t kViews = 240;
constexpr uint32_t kRolls = 16;

std::shared_ptr<const Database> TestDatabase() {
  static const auto db = std::make_shared<const Database>(
      SyntheticDatabase(kViews, /*points=*/150, kRolls, /*views_per_shape=*/12));
  return db;
}

IndexBuildOptions BuildOptions() {
  IndexBuildOptions o;
  o.grid.cell_units = 256;  // 16 px cells, 15 x 15 (+-120 px): a fast PCA for a test
  o.grid.side = 15;
  o.dims = 24;
  o.nlist = 16;
  o.num_threads = 2;
  return o;
}

const ViewIndex& TestIndex() {
  static const ViewIndex index = [] {
    auto built = ViewIndex::Build(*TestDatabase(), BuildOptions());
    THROW_CHECK(built.ok());
    return std::move(built).value();
  }();
  return index;
}

// A query made from view v at roll r, shifted and thinned like a real edge map would be.
std::vector<Point2f> Perturbed(view_id_t v, roll_id_t r, uint32_t seed) {
  std::vector<Point2f> pts = RolledView(*TestDatabase(), v, r);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> jitter(-1.5f, 1.5f);
  std::vector<Point2f> out;
  for (size_t i = 0; i < pts.size(); ++i) {
    if (i % 5 == 0) continue;
    out.push_back({pts[i].x + 2.0f + jitter(rng), pts[i].y - 1.0f + jitter(rng)});
  }
  return out;
}

// Each term of the embedding's inner product replaces a point's distance by its cell centre's,
// and distances are 1-Lipschitz: with every point on the grid, |<u, e> - D_c| <= one cell
// diagonal (half a diagonal per term).
TEST(Embedding, InnerProductIsWithinACellDiagonalOfTheChamferDistance) {
  const Database& db = *TestDatabase();
  EmbeddingGrid grid;  // 8 px cells, +-124 px: holds every synthetic hand
  std::vector<float> u(grid.dims()), e(grid.dims());
  const double diagonal = std::sqrt(2.0) * grid.cell_units / kPointScale;
  int checked = 0;
  double worst = 0;
  for (view_id_t q = 0; q < kViews; q += 37) {
    const std::vector<Point2f> query = Perturbed(q, 3, q);
    for (roll_id_t r = 0; r < kRolls; r += 5) {
      const std::vector<PointQ> rolled = RotateAndQuantise(query, -RollAngle(r, kRolls));
      QueryVector(grid, rolled, 3.0f, u.data());
      for (view_id_t v = 0; v < kViews; v += 11) {
        ViewVector(grid, db.points(v), 3.0f, e.data());
        double approx = 0;
        for (int j = 0; j < grid.dims(); ++j) approx += static_cast<double>(u[j]) * e[j];
        const double exact = ChamferBruteForce(rolled, db.points(v)).total();
        EXPECT_LE(std::fabs(approx - exact), diagonal + 1e-3) << "view " << v << " roll " << r;
        worst = std::max(worst, std::fabs(approx - exact));
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 100);
  EXPECT_GT(worst, 0.0);
}

TEST(Embedding, CentreDistancesAreExact) {
  EmbeddingGrid grid;
  grid.side = 5;
  const std::vector<PointQ> pts = {{0, 0}, {300, -40}, {-700, 900}};
  std::vector<float> g(grid.cells());
  CentreDistances(grid, pts, g.data());
  for (int iy = 0; iy < grid.side; ++iy) {
    for (int ix = 0; ix < grid.side; ++ix) {
      double best = 1e30;
      for (const PointQ& p : pts) {
        best = std::min(best, std::hypot(p.x - grid.Centre(ix), p.y - grid.Centre(iy)) / 16.0);
      }
      EXPECT_FLOAT_EQ(g[iy * grid.side + ix], static_cast<float>(best));
    }
  }
  EXPECT_EQ(grid.ClampedCell({0, 0}), 12);           // the centre cell
  EXPECT_EQ(grid.ClampedCell({-32000, 32000}), 20);  // clamped to the bottom-left corner
}

TEST(ViewIndex, BuildIsDeterministicAndSerialisesRoundTrip) {
  auto again = ViewIndex::Build(*TestDatabase(), BuildOptions());
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  const std::string bytes = TestIndex().Serialize();
  EXPECT_EQ(bytes, again->Serialize());
  const Database& db = *TestDatabase();
  auto parsed =
      ViewIndex::Parse(bytes, DatabaseFingerprint(db.manifest()), kViews, kRolls, "test.hdbi");
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_EQ(parsed->dims(), 24);
  EXPECT_EQ(parsed->nlist(), 16);
  EXPECT_EQ(parsed->Serialize(), bytes);
  IndexSearchOptions so;
  so.candidates = 50;
  const std::vector<Point2f> query = Perturbed(17, 5, 1);
  const auto a = TestIndex().Candidates(query, so);
  const auto b = parsed->Candidates(query, so);
  ASSERT_EQ(a.size(), 50u);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].view, b[i].view);
    EXPECT_EQ(a[i].roll, b[i].roll);
    EXPECT_EQ(a[i].score, b[i].score);
    if (i > 0) {
      EXPECT_LE(a[i - 1].score, a[i].score);
    }
  }
}

// The batched scan of every view (nprobe 0) and the IVF probe of every list compute each inner
// product the same way: the same candidates and scores, whatever the number of threads.
TEST(ViewIndex, BatchedScanEqualsTheProbeOfEveryListForAnyThreads) {
  const std::vector<Point2f> query = Perturbed(101, 9, 3);
  IndexSearchOptions so;
  so.candidates = 300;
  so.num_threads = 1;
  const auto want = TestIndex().Candidates(query, so);
  ASSERT_EQ(want.size(), 300u);
  for (int threads : {1, 2, 3}) {
    for (int nprobe : {0, 16, 99}) {
      if (threads == 1 && nprobe == 0) continue;
      so.num_threads = threads;
      so.nprobe = nprobe;
      const auto got = TestIndex().Candidates(query, so);
      ASSERT_EQ(got.size(), want.size()) << "threads " << threads << " nprobe " << nprobe;
      for (size_t i = 0; i < got.size(); ++i) {
        EXPECT_EQ(got[i].view, want[i].view) << i;
        EXPECT_EQ(got[i].roll, want[i].roll) << i;
        EXPECT_EQ(got[i].score, want[i].score) << i;
      }
    }
  }
  // Fewer lists find a subset, each with the same score.
  so.nprobe = 4;
  const auto few = TestIndex().Candidates(query, so);
  ASSERT_EQ(few.size(), 300u);
  std::set<std::pair<view_id_t, roll_id_t>> seen;
  for (const Candidate& c : want) seen.insert({c.view, c.roll});
  size_t shared = 0;
  for (const Candidate& c : few) shared += seen.count({c.view, c.roll});
  EXPECT_GT(shared, 0u);
  EXPECT_LE(few.front().score, few.back().score);
  EXPECT_GE(few.front().score, want.front().score);
}

// Asking for more candidates than there are pairs gives every pair once.
TEST(ViewIndex, AllPairsWhenTheCandidatesExceedThem) {
  IndexSearchOptions so;
  so.candidates = static_cast<int>(kViews * kRolls) + 100;
  const auto all = TestIndex().Candidates(Perturbed(3, 1, 2), so);
  ASSERT_EQ(all.size(), static_cast<size_t>(kViews) * kRolls);
  std::set<std::pair<view_id_t, roll_id_t>> seen;
  for (const Candidate& c : all) {
    EXPECT_LT(c.view, kViews);
    seen.insert({c.view, c.roll});
  }
  EXPECT_EQ(seen.size(), all.size());
}

TEST(ViewIndex, ParseRefusesDamagedOrForeignFiles) {
  const Database& db = *TestDatabase();
  const uint64_t fp = DatabaseFingerprint(db.manifest());
  const std::string good = TestIndex().Serialize();
  auto code = [&](const std::string& bytes, uint64_t fingerprint = 0, uint64_t views = kViews) {
    auto r = ViewIndex::Parse(bytes, fingerprint == 0 ? fp : fingerprint, views, kRolls, "x.hdbi");
    EXPECT_FALSE(r.ok());
    if (!r.ok()) {
      EXPECT_EQ(r.status().message().rfind("x.hdbi: ", 0), 0u) << r.status().message();
    }
    return r.ok() ? StatusCode::kOk : r.status().code();
  };
  EXPECT_EQ(code(good.substr(0, 100)), StatusCode::kTruncated);
  EXPECT_EQ(code(good.substr(0, good.size() - 1)), StatusCode::kTruncated);
  std::string bad = good;
  bad[0] = 'X';
  EXPECT_EQ(code(bad), StatusCode::kBadMagic);
  for (size_t off : {size_t{200}, good.size() / 2, good.size() - 1}) {
    bad = good;
    bad[off] ^= 0x40;
    EXPECT_EQ(code(bad), StatusCode::kChecksumMismatch) << "byte " << off;
  }
  bad = good;
  bad[44] ^= 1;  // a header field: the header checksum catches it
  EXPECT_EQ(code(bad), StatusCode::kChecksumMismatch);
  EXPECT_EQ(code(good, fp ^ 1), StatusCode::kSizeMismatch);
  EXPECT_EQ(code(good, 0, kViews + 1), StatusCode::kSizeMismatch);
}

// Like shards (docs/format.md, "Versioning"): a newer minor of our major is read, and its reserved
// bytes may carry meaning; in a file of our own minor they must be zero.
TEST(ViewIndex, ParseReadsANewerMinorAndChecksReservedBytesOnlyForItsOwn) {
  const Database& db = *TestDatabase();
  const uint64_t fp = DatabaseFingerprint(db.manifest());
  auto with_header = [](std::string bytes, size_t off, uint8_t value) {
    bytes[off] = static_cast<char>(value);
    const uint64_t sum = XXH3_64bits(bytes.data(), 120);
    std::memcpy(bytes.data() + 120, &sum, 8);
    return bytes;
  };
  const std::string good = TestIndex().Serialize();
  const std::string reserved = with_header(good, 100, 7);
  auto r = ViewIndex::Parse(reserved, fp, kViews, kRolls, "x.hdbi");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNonZeroReserved);
  const std::string newer = with_header(reserved, 10, 3);  // version 1.3
  r = ViewIndex::Parse(newer, fp, kViews, kRolls, "x.hdbi");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->Serialize(), good);  // written back as the version this writer knows
  r = ViewIndex::Parse(with_header(good, 8, 2), fp, kViews, kRolls, "x.hdbi");  // version 2.0
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kUnsupportedVersion);
}

SearchOptions Options(SearchMode mode, int candidates) {
  SearchOptions o;
  o.top_k = 5;
  o.num_threads = 2;
  o.mode = mode;
  o.index.candidates = candidates;
  o.index.nprobe = 16;  // every list: the candidates are the exact top by the approximate bound
  return o;
}

// With every pair a candidate, indexed search is exact search (also with one match per shape).
TEST(IndexedSearch, AllPairsAsCandidatesGiveTheExactResult) {
  Searcher searcher(TestDatabase());
  searcher.SetIndex(std::make_shared<ViewIndex>(
      std::move(ViewIndex::Parse(TestIndex().Serialize(),
                                 DatabaseFingerprint(TestDatabase()->manifest()),
                                 kViews,
                                 kRolls,
                                 "t")
                    .value())));
  for (Hand hand : {Hand::kRight, Hand::kLeft, Hand::kEither}) {
    for (view_id_t v : {3u, 100u, 211u}) {
      const std::vector<Point2f> query = Perturbed(v, 7, v + 1);
      SearchOptions exact = Options(SearchMode::kExact, 1);
      SearchOptions indexed = Options(SearchMode::kIndexed, kViews * kRolls);
      exact.hand = indexed.hand = hand;
      exact.max_per_shape = indexed.max_per_shape = static_cast<int>(v % 2);
      SearchStats stats;
      auto a = searcher.Search(query, exact);
      auto b = searcher.Search(query, indexed, &stats);
      ASSERT_TRUE(a.ok() && b.ok());
      ASSERT_EQ(a->size(), b->size());
      for (size_t i = 0; i < a->size(); ++i) {
        EXPECT_EQ((*a)[i].view_id, (*b)[i].view_id) << "rank " << i;
        EXPECT_EQ((*a)[i].roll, (*b)[i].roll) << "rank " << i;
        EXPECT_EQ((*a)[i].distance, (*b)[i].distance) << "rank " << i;
        EXPECT_EQ((*a)[i].hand, (*b)[i].hand) << "rank " << i;
      }
      EXPECT_EQ(stats.candidates, uint64_t{kViews} * kRolls * stats.searches);
    }
  }
}

// Few candidates: the query's own view is still found (the embedding ranks it near the top), and
// the result is the exact top-k of the candidates: never better than exact search.
TEST(IndexedSearch, FewCandidatesFindTheSourceView) {
  Searcher searcher(TestDatabase());
  searcher.SetIndex(std::shared_ptr<const ViewIndex>(&TestIndex(), [](const ViewIndex*) {}));
  int found = 0, total = 0;
  for (view_id_t v = 1; v < kViews; v += 17) {
    const roll_id_t r = static_cast<roll_id_t>(v % kRolls);
    const std::vector<Point2f> query = Perturbed(v, r, v);
    SearchStats stats;
    auto exact = searcher.Search(query, Options(SearchMode::kExact, 1));
    auto indexed = searcher.Search(query, Options(SearchMode::kIndexed, 40), &stats);
    ASSERT_TRUE(exact.ok() && indexed.ok());
    EXPECT_EQ(stats.candidates, 40u);
    EXPECT_LE(stats.bounded, 40u);
    for (size_t i = 0; i < indexed->size(); ++i) {
      EXPECT_GE((*indexed)[i].distance, (*exact)[i].distance) << "rank " << i;
    }
    found += (*indexed)[0].view_id == (*exact)[0].view_id && (*indexed)[0].roll == (*exact)[0].roll;
    ++total;
  }
  // 40 of 3,840 pairs (1%): measured 14 of 14.
  EXPECT_GE(found, total * 3 / 4) << found << " of " << total;
}

// Few candidates: the result is the top-k by D_c of exactly the index's candidates, the left
// hand's from the mirrored query, both hands' merged in one order (D_c, view, roll, right first).
TEST(IndexedSearch, ResultIsTheTopKOfTheCandidates) {
  const Database& db = *TestDatabase();
  Searcher searcher(TestDatabase());
  searcher.SetIndex(std::shared_ptr<const ViewIndex>(&TestIndex(), [](const ViewIndex*) {}));
  struct Pair {
    double distance;
    view_id_t view;
    roll_id_t roll;
    Hand hand;
  };
  for (view_id_t v : {5u, 60u, 170u}) {
    const std::vector<Point2f> query = Perturbed(v, 11, v + 3);
    for (Hand hand : {Hand::kRight, Hand::kEither}) {
      SearchOptions options = Options(SearchMode::kIndexed, 30);
      options.hand = hand;
      options.index.nprobe = 4;
      std::vector<Pair> expected;
      for (Hand h : {Hand::kRight, Hand::kLeft}) {
        if (hand != Hand::kEither && h != hand) continue;
        std::vector<Point2f> q = query;
        if (h == Hand::kLeft) {
          for (Point2f& p : q) p.x = -p.x;
        }
        for (const Candidate& c : TestIndex().Candidates(q, options.index)) {
          const std::vector<PointQ> rolled = RotateAndQuantise(q, -RollAngle(c.roll, kRolls));
          expected.push_back(
              {ChamferBruteForce(rolled, db.points(c.view)).total(), c.view, c.roll, h});
        }
      }
      std::sort(expected.begin(), expected.end(), [](const Pair& x, const Pair& y) {
        if (x.distance != y.distance) return x.distance < y.distance;
        if (x.view != y.view) return x.view < y.view;
        if (x.roll != y.roll) return x.roll < y.roll;
        return x.hand == Hand::kRight && y.hand == Hand::kLeft;
      });
      SearchStats stats;
      auto got = searcher.Search(query, options, &stats);
      ASSERT_TRUE(got.ok()) << got.status().ToString();
      ASSERT_EQ(got->size(), 5u);
      EXPECT_EQ(stats.candidates, 30u * stats.searches);
      for (size_t i = 0; i < got->size(); ++i) {
        EXPECT_EQ((*got)[i].view_id, expected[i].view) << "view " << v << " rank " << i;
        EXPECT_EQ((*got)[i].roll, expected[i].roll) << "view " << v << " rank " << i;
        EXPECT_EQ((*got)[i].hand, expected[i].hand) << "view " << v << " rank " << i;
        EXPECT_NEAR((*got)[i].distance, expected[i].distance, 1e-9) << "view " << v;
      }
    }
  }
}

TEST(IndexedSearch, WithoutAnIndexIsAClearError) {
  Searcher searcher(TestDatabase());
  auto r = searcher.Search(Perturbed(1, 1, 1), Options(SearchMode::kIndexed, 10));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("handdb index"), std::string::npos) << r.status().message();
}

}  // namespace
}  // namespace handdb
