#include "query/coarse_bound.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "format/shard_testing.h"
#include "query/chamfer.h"
#include "query/database.h"
#include "query/distance_transform.h"
#include "query/search_testing.h"
#include "query/searcher.h"

namespace handdb {
namespace {

using testing::RandomPoints;

// L_A <= A for random pairs, and it is not vacuous: a query far from the view gets most of A.
TEST(CoarseBound, HistogramBoundIsBelowTheExactQueryToViewTerm) {
  std::mt19937 rng(11);
  std::vector<uint8_t> field(CoarseGrid::kCells);
  CellHistogram hist;
  double worst_gap = 0;
  for (int i = 0; i < 200; ++i) {
    const auto view = RandomPoints(&rng, 100 + i % 300, 400 + 10 * i);
    const auto query = RandomPoints(&rng, 50 + i % 200, 300 + 15 * i);
    ComputeCoarseField(view, field.data());
    hist.Build(query);
    const double bound = hist.LowerBound(field.data(), query.size());
    const double a = ChamferBruteForce(query, view).a;
    ASSERT_LE(bound, a) << "pair " << i;
    // The loss per point is at most the cell's diagonal, for points on the grid whose distance
    // is below the 127.5 px saturation.
    bool tight = true;
    for (const PointQ& q : query) {
      const double d = std::sqrt(static_cast<double>(NearestSquaredSmall(q, view))) / kPointScale;
      if (CoarseGrid::CellOf(q) < 0 || d >= 127) tight = false;
    }
    if (tight) worst_gap = std::max(worst_gap, a - bound);
  }
  EXPECT_GT(worst_gap, 0);
  EXPECT_LE(worst_gap, 8 * std::sqrt(2.0) + 0.5);

  const std::vector<PointQ> view = {{0, 0}};
  const std::vector<PointQ> far = {{1600, 0}, {0, -1600}};  // 100 px away
  ComputeCoarseField(view, field.data());
  hist.Build(far);
  EXPECT_GE(hist.LowerBound(field.data(), far.size()), 100 - 8 * std::sqrt(2.0));
}

// Reflects points in x, y or both (the flips of one distance grid's slots).
std::vector<PointQ> Flipped(std::span<const PointQ> points, GridFlip flip) {
  std::vector<PointQ> out(points.begin(), points.end());
  for (PointQ& p : out) {
    if (flip == GridFlip::kX || flip == GridFlip::kXY) p.x = static_cast<int16_t>(-p.x);
    if (flip == GridFlip::kY || flip == GridFlip::kXY) p.y = static_cast<int16_t>(-p.y);
  }
  return out;
}

// L_Bc: every view's sums for every slot are sum_c n_v(c) G_s(c) (the plain formula), below the
// exact view -> query term B, and not vacuous; a flipped or quarter-turned copy of a slot's field
// is the field of the flipped or turned query (the grid is symmetric), and a gap lowers every
// value by its ceiling.
TEST(CoarseBound, ViewHistogramSumsAreBelowTheExactViewToQueryTerm) {
  const auto db = testing::SyntheticDatabase(60, 300, 4, /*views_per_shape=*/10);
  const ViewHistograms histograms(db, 2);
  ASSERT_EQ(histograms.num_views(), 60u);
  std::mt19937 rng(5);
  constexpr size_t kSlots = 37;  // not a multiple of 32: the padding slots must read 0
  SlotFields fields;
  fields.Reset(kSlots);
  EXPECT_EQ(fields.stride(), 64u);
  std::vector<std::vector<PointQ>> queries;
  for (size_t s = 0; s < kSlots; ++s) {
    queries.push_back(RandomPoints(&rng, 30 + 7 * s, 200 + 40 * s));
    fields.Compute(s, queries.back());
  }
  std::vector<uint8_t> field(CoarseGrid::kCells);
  for (size_t s = 0; s < kSlots; ++s) {  // Compute stores ComputeCoarseField's values
    ComputeCoarseField(queries[s], field.data());
    for (int c = 0; c < CoarseGrid::kCells; ++c) ASSERT_EQ(fields.value(s, c), field[c]);
  }
  std::vector<uint32_t> sums(fields.stride());
  double worst_gap = 0;
  for (view_id_t v = 0; v < db.num_views(); ++v) {
    const std::span<const PointQ> view = db.points(v);
    histograms.Sums(v, fields, sums.data());
    for (size_t s = kSlots; s < fields.stride(); ++s) ASSERT_EQ(sums[s], 0u);
    for (size_t s = 0; s < kSlots; ++s) {
      uint64_t plain = 0;
      for (const PointQ& y : view) {
        const int c = CoarseGrid::CellOf(y);
        if (c >= 0) plain += fields.value(s, c);
      }
      ASSERT_EQ(sums[s], plain) << "view " << v << " slot " << s;
      const double bound = static_cast<double>(plain) / CoarseGrid::kValueUnitsPerPx /
                           static_cast<double>(view.size());
      const double b = ChamferBruteForce(queries[s], view).b;
      ASSERT_LE(bound, b) << "view " << v << " slot " << s;
      worst_gap = std::max(worst_gap, b - bound);
    }
  }
  EXPECT_GT(worst_gap, 0);
  EXPECT_LE(worst_gap, 8 * std::sqrt(2.0) + 0.5);

  for (GridFlip flip : {GridFlip::kX, GridFlip::kY, GridFlip::kXY}) {
    fields.CopyFlipped(3, 4, flip, 0.0);
    ComputeCoarseField(Flipped(queries[3], flip), field.data());
    for (int c = 0; c < CoarseGrid::kCells; ++c) ASSERT_EQ(fields.value(4, c), field[c]);
    fields.CopyFlipped(3, 5, flip, 1.2);  // 2.4 half px: 3 off, saturating at 0
    for (int c = 0; c < CoarseGrid::kCells; ++c) {
      ASSERT_EQ(fields.value(5, c), std::max(0, field[c] - 3));
    }
  }
  // The quarter turn T(x, y) = (y, -x): roll r + R/4 of roll r.
  std::vector<PointQ> turned = queries[6];
  for (PointQ& p : turned) p = PointQ{p.y, static_cast<int16_t>(-p.x)};
  fields.CopyQuarterTurned(6, 7, 0.0);
  ComputeCoarseField(turned, field.data());
  for (int c = 0; c < CoarseGrid::kCells; ++c) ASSERT_EQ(fields.value(7, c), field[c]);
  fields.CopyQuarterTurned(6, 8, 0.3);  // 0.6 half px: 1 off
  for (int c = 0; c < CoarseGrid::kCells; ++c) {
    ASSERT_EQ(fields.value(8, c), std::max(0, field[c] - 1));
  }
}

// The neighbour bound of one point is below its exact distance to the view, never below the own
// cell's value, and above it for many points (so it prunes more); the cell-major copy holds the
// fields the shards would (ComputeCoarseField).
// The same for the centre field (FieldKind::kCentre): below the exact distance, never below the
// own cell's term, and larger than the box field's point bound on the whole for points within
// reach of the hand (the mean of real queries' refined pairs: 4.53 -> 4.90 px, docs/query.md).
TEST(CoarseBound, PointBoundIsBelowTheExactDistanceAndAboveTheCellValue) {
  const auto db = testing::SyntheticDatabase(150, 300, 4, /*views_per_shape=*/10);
  const CoarseFields fields(db, 2);
  const CoarseFields centres(db, 2, FieldKind::kCentre);
  EXPECT_EQ(fields.num_views(), 150u);
  EXPECT_EQ(fields.computed_views(), 150u);  // in memory: no shard sections
  EXPECT_EQ(centres.kind(), FieldKind::kCentre);
  std::mt19937 rng(9);
  std::vector<uint8_t> want(CoarseGrid::kCells);
  std::vector<uint8_t> want_centres(CoarseGrid::kCells);
  size_t better = 0;
  uint64_t near_box = 0;
  uint64_t near_centre = 0;
  size_t total = 0;
  for (view_id_t v = 0; v < db.num_views(); v += 7) {
    ComputeCoarseField(db.points(v), want.data());
    ComputeCentreField(db.points(v), want_centres.data());
    for (int c = 0; c < CoarseGrid::kCells; ++c) {
      ASSERT_EQ(fields.value(v, c), want[c]);
      ASSERT_EQ(centres.value(v, c), want_centres[c]);
    }
    for (const PointQ& q : RandomPoints(&rng, 2000, 180 * 16)) {
      const int bound = fields.PointLowerBound(v, q);
      const int centre_bound = centres.PointLowerBound(v, q);
      const double exact =
          std::sqrt(static_cast<double>(NearestSquaredSmall(q, db.points(v)))) / kPointScale;
      ASSERT_LE(bound / CoarseGrid::kValueUnitsPerPx, exact) << v << ": " << q.x << "," << q.y;
      ASSERT_LE(centre_bound / CoarseGrid::kValueUnitsPerPx, exact)
          << v << ": " << q.x << "," << q.y;
      const int c = CoarseGrid::CellOf(q);
      if (c < 0) {
        EXPECT_EQ(bound, 0);
        EXPECT_EQ(centre_bound, 0);
        continue;
      }
      ASSERT_GE(bound, fields.value(v, c));
      uint8_t gaps[9];
      FieldGaps(FieldKind::kCentre, q, gaps);
      ASSERT_GE(centre_bound, centres.value(v, c) - gaps[8]);
      better += bound > fields.value(v, c);
      if (exact < 20) {  // within reach of the hand: where the bounds decide
        near_box += static_cast<uint64_t>(bound);
        near_centre += static_cast<uint64_t>(centre_bound);
      }
      ++total;
    }
  }
  EXPECT_GT(better, total / 4);
  EXPECT_GT(near_centre, near_box);
}

// A point's gaps to the centres of its cell and its neighbours are its distances to them,
// rounded up to 1/2 px; to boxes, NeighbourGaps and 0 for its own.
TEST(CoarseBound, FieldGapsAreTheDistancesRoundedUp) {
  std::mt19937 rng(3);
  for (const PointQ& q : RandomPoints(&rng, 5000, 170 * 16)) {
    const int c = CoarseGrid::CellOf(q);
    if (c < 0) continue;
    uint8_t box[9];
    uint8_t nb[8];
    FieldGaps(FieldKind::kBox, q, box);
    NeighbourGaps(q, nb);
    ASSERT_EQ(box[8], 0);
    for (int k = 0; k < 8; ++k) ASSERT_EQ(box[k], nb[k]);
    uint8_t centre[9];
    FieldGaps(FieldKind::kCentre, q, centre);
    const int ix = c % CoarseGrid::kSide;
    const int iy = c / CoarseGrid::kSide;
    int k = 0;
    for (int oy = -1; oy <= 1; ++oy) {
      for (int ox = -1; ox <= 1; ++ox) {
        const double cx = -CoarseGrid::kHalfUnits + (ix + ox) * CoarseGrid::kCellUnits + 64;
        const double cy = -CoarseGrid::kHalfUnits + (iy + oy) * CoarseGrid::kCellUnits + 64;
        const double units = std::hypot(q.x - cx, q.y - cy) / 8;  // 1/2 px
        const uint8_t got = ox == 0 && oy == 0 ? centre[8] : centre[k++];
        ASSERT_GE(got, units - 1e-9) << q.x << "," << q.y << " " << ox << "," << oy;
        ASSERT_LT(got, units + 1) << q.x << "," << q.y << " " << ox << "," << oy;
      }
    }
  }
}

// L_A's streaming product is PairSum exactly, for every view of a full and a partial block (views
// past the end get 0), and without the neighbour terms the cell-only sum; only the groups of 32
// views asked for are written; PairSum lies between the cell-only sum of n_i (F_v(c) - own gap)
// and the sum of the points' own bounds (CoarseFields::PointLowerBound), which the exact
// distances exceed (PointBoundIsBelowTheExactDistanceAndAboveTheCellValue). For box fields and
// for centre fields. A cell holding more than kMaxCount points (listed more than once) is
// covered, and so are points on the grid's border cells and off the grid.
void CheckBlockSums(const Database& db, FieldKind kind) {
  const CoarseFields fields(db, 2, kind);
  ASSERT_EQ(fields.num_blocks(), 2u);
  std::mt19937 rng(11);
  std::vector<PointQ> query = RandomPoints(&rng, 3000, 120 * 16);
  query.insert(query.end(), 300, PointQ{5 * 16, -7 * 16});  // one cell far above kMaxCount
  const std::vector<PointQ> border = RandomPoints(&rng, 200, 180 * 16);  // border and off-grid
  query.insert(query.end(), border.begin(), border.end());
  CellHistogram hist;
  hist.Build(query, kind);
  std::vector<uint32_t> sums(CoarseFields::kBlock);
  std::vector<uint32_t> cell_sums(CoarseFields::kBlock);
  std::vector<uint32_t> some(CoarseFields::kBlock, 7);
  uint64_t tighter = 0;
  for (size_t b = 0; b < fields.num_blocks(); ++b) {
    fields.BlockSums(hist, b, sums.data());
    fields.BlockSums(hist, b, cell_sums.data(), /*neighbours=*/false);
    // Only the groups of 32 views asked for are written.
    fields.BlockSums(hist, b, some.data(), /*neighbours=*/true, /*groups=*/0b0101);
    for (size_t i = 0; i < CoarseFields::kBlock; ++i) {
      ASSERT_EQ(some[i], (i / 32) % 2 == 0 ? sums[i] : 7u) << "block " << b << " view " << i;
    }
    for (size_t i = 0; i < CoarseFields::kBlock; ++i) {
      const size_t v = b * CoarseFields::kBlock + i;
      if (v >= fields.num_views()) {
        ASSERT_EQ(sums[i], 0u) << "view " << v;
        continue;
      }
      // The cell-only sum: n_i (F_v(c) - own gap) per entry (the own gap is 0 for boxes).
      uint64_t cell_only = 0;
      for (size_t e = 0; e < hist.num_cells(); ++e) {
        cell_only +=
            static_cast<uint64_t>(hist.counts()[e]) *
            static_cast<uint64_t>(std::max(0, fields.value(v, hist.cells()[e]) - hist.own_gap(e)));
      }
      uint64_t point_bounds = 0;
      for (const PointQ& q : query) {
        point_bounds += static_cast<uint64_t>(fields.PointLowerBound(v, q));
      }
      const uint64_t pair = fields.PairSum(hist, v);
      ASSERT_EQ(sums[i], pair) << "view " << v;
      ASSERT_GE(pair, cell_only) << "view " << v;
      ASSERT_LE(pair, point_bounds) << "view " << v;
      if (kind == FieldKind::kBox) {
        ASSERT_EQ(hist.Sum([&](int c) { return fields.value(v, c); }), cell_only);
      }
      ASSERT_EQ(cell_sums[i], cell_only) << "view " << v;
      tighter += pair > cell_only;
    }
  }
  EXPECT_GT(tighter, fields.num_views() / 2);  // the neighbour terms do tighten the bound
}

TEST(CoarseBound, BlockSumsArePairSumsBetweenTheCellAndThePointBounds) {
  const auto db = testing::SyntheticDatabase(150, 300, 4, /*views_per_shape=*/10);
  CheckBlockSums(db, FieldKind::kBox);
  CheckBlockSums(db, FieldKind::kCentre);
}

// Queries with edges the views lack (clutter) are where the A bound matters: pruned search with
// it equals brute force, and refines fewer pairs than the B bound alone.
TEST(CoarseBound, SearchWithClutterEqualsBruteForceAndRefinesLess) {
  const auto db = std::make_shared<const Database>(
      testing::SyntheticDatabase(40, 150, 12, /*views_per_shape=*/8));
  const Searcher searcher(db);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-120, 120);
  uint64_t refined_with = 0;
  uint64_t refined_without = 0;
  for (int i = 0; i < 12; ++i) {
    std::vector<Point2f> q = testing::RolledView(*db, static_cast<view_id_t>(i * 3), i % 12);
    const size_t clutter = q.size() / 2;
    for (size_t c = 0; c < clutter; ++c) q.push_back({u(rng), u(rng)});
    SearchOptions with;
    with.top_k = 1 + i % 5;
    with.num_threads = 1 + i % 2;
    SearchOptions without = with;
    without.coarse_bound = false;
    SearchOptions brute = with;
    brute.brute_force = true;
    SearchStats s_with;
    SearchStats s_without;
    auto a = searcher.Search(q, with, &s_with);
    auto b = searcher.Search(q, without, &s_without);
    auto c = searcher.Search(q, brute);
    ASSERT_TRUE(a.ok() && b.ok() && c.ok());
    ASSERT_EQ(a->size(), c->size());
    for (size_t k = 0; k < a->size(); ++k) {
      EXPECT_EQ((*a)[k].view_id, (*c)[k].view_id) << "query " << i << " rank " << k;
      EXPECT_EQ((*a)[k].roll, (*c)[k].roll);
      EXPECT_EQ((*a)[k].distance, (*c)[k].distance);
      EXPECT_EQ((*b)[k].distance, (*c)[k].distance);
      EXPECT_LE((*a)[k].lower_bound, (*a)[k].distance);
    }
    refined_with += s_with.refined;
    refined_without += s_without.refined;
  }
  EXPECT_LT(refined_with, refined_without);
}

}  // namespace
}  // namespace handdb
