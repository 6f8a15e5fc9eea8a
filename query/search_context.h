// The per-query context of a search (query/searcher.h): every slot's rolled query (a slot is a
// (hand, roll): the query, mirrored for the left hand, rolled into the canonical frame), what the
// bounds read of it, the per-worker caches of view structures, and the exact D_c of one pair
// (Score), abandoned as soon as it provably exceeds the k-th best. Internal to query/.
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include "format/view.h"
#include "query/chamfer.h"
#include "query/coarse_bound.h"
#include "query/database.h"
#include "query/distance_transform.h"
#include "query/kdtree.h"
#include "query/point_buckets.h"
#include "query/searcher.h"
#include "query/top_k.h"
#include "query/view_lru.h"

namespace handdb::search_internal {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Relative slack on abandonment thresholds so float rounding can never drop a pair that ties
// the k-th best (abandoning is only ever allowed for pairs strictly worse than it).
constexpr double kAbandonSlack = 1e-12;

// Lower bounds are stored per (view, roll) as uint16 in 1/64 px, rounded down (a lower bound
// stays a lower bound) and saturating at kBoundMax (1023.98 px, still a valid bound); kNoBound
// marks a view without points. Two bytes per virtual view instead of four: on the paper database
// the array is 215 KB, 3.6% of the database.
using Bound = uint16_t;
constexpr Bound kNoBound = 0xFFFF;
constexpr Bound kBoundMax = 0xFFFE;
constexpr double kBoundUnitsPerPx = 64.0;

inline Bound BoundBelow(double px) {
  const double units = std::floor(std::max(0.0, px) * kBoundUnitsPerPx);
  return static_cast<Bound>(std::min(units, static_cast<double>(kBoundMax)));
}
inline double BoundPx(Bound b) { return static_cast<double>(b) / kBoundUnitsPerPx; }

// The largest partial sum over n terms that can still give known + sum / n <= threshold, with
// slack so rounding never abandons a pair that ties the threshold; negative: already above.
inline double Limit(double threshold, double known, double n) {
  if (threshold == kInf) return kInf;
  return (threshold - known) * n * (1 + kAbandonSlack) + kAbandonSlack;
}

// An upper bound (PointQ units) of d(q, Y_v) for q in a cell with coarse value F (1/2 px, rounded
// down, so the true distance is below F + 1/2 px). Boxes: the box's nearest point to Y_v is that
// far, and q is at most the box's diagonal (8 sqrt 2 px, 181.02 units) from it. Centres: q is at
// most half the diagonal (90.51 units) from its cell's centre.
inline int32_t NearestWithin(FieldKind kind, uint8_t coarse_value) {
  return static_cast<int32_t>(coarse_value) * (kPointScale / 2) + kPointScale / 2 +
         (kind == FieldKind::kBox ? 182 : 91);
}

// Where each 1 px row of the coarse grid starts in a view's points sorted by y (every converted
// view: edges/view_conversion.h): the points with y in [y0, y1] are [start[row(y0)],
// start[row(y1) + 1]), found with two lookups. A query point whose nearest view point is known to
// be within r scans only the rows within r of it: no kd-tree or bucket sort to build per view,
// ~1,000 instructions to index one (docs/query.md).
class RowIndex {
 public:
  static constexpr int kRowUnits = 16;
  static constexpr int kRows = 2 * CoarseGrid::kHalfUnits / kRowUnits;
  void Build(std::span<const PointQ> points) {
    start_.assign(kRows + 1, 0);
    uint32_t i = 0;
    for (int row = 0; row < kRows; ++row) {
      const int y_end = -CoarseGrid::kHalfUnits + (row + 1) * kRowUnits;  // exclusive
      while (i < points.size() && points[i].y < y_end) ++i;
      start_[static_cast<size_t>(row) + 1] = i;
    }
  }
  // Exact nearest squared distance from q to `points` (the set Build saw), given that one point
  // is within `radius` units of q: only the rows within radius of q.y are scanned.
  int32_t NearestSquared(PointQ q, std::span<const PointQ> points, int32_t radius) const {
    const int r0 = std::max(0, (q.y - radius + CoarseGrid::kHalfUnits) / kRowUnits);
    const int r1 = std::min(kRows - 1, (q.y + radius + CoarseGrid::kHalfUnits) / kRowUnits);
    if (q.y - radius + CoarseGrid::kHalfUnits >= 0 && r0 <= r1) {
      const uint32_t lo = start_[static_cast<size_t>(r0)];
      const uint32_t hi = start_[static_cast<size_t>(r1) + 1];
      if (lo < hi) {
        const int32_t best = NearestSquaredSmall(q, points.subspan(lo, hi - lo));
        if (best <= radius * radius) return best;
      }
    }
    return NearestSquaredSmall(q, points);
  }

 private:
  std::vector<uint32_t> start_;
};

// A (hand, roll) combination searched: the query, mirrored for the left hand, rolled by
// -angle(roll). Hand::kEither searches the 2R slots of both hands in one run.
struct Slot {
  Hand hand = Hand::kRight;
  roll_id_t roll = 0;
};

// A slot that reads another slot's distance grid: the grid of the base slot's rolled query Q_b,
// read at flip(y), bounds d(y, flip(Q_b)), and the member's own rolled query is flip(Q_b) up to
// `gap_px` per point (rounding ties; 0 in practice), so d(y, Q_m) >= d(flip(y), Q_b) - gap.
// A turned member is flip(T(Q_b)) up to its gap, T(x, y) = (y, -x), and reads the grid at
// T^-1(flip(y)) (DistanceGrid::LowerBound).
struct GridMember {
  uint32_t slot = 0;
  GridFlip flip = GridFlip::kNone;
  bool turned = false;
  double gap_px = 0;  // set once the slots are prepared
};

// Per-query state shared by the workers: every slot's rolled query, its coarse histogram and
// the point cells the linear scans read, and (lazily) its kd-tree.
class SearchContext {
 public:
  SearchContext(const Database& db,
                std::span<const int32_t> max_abs,
                std::span<const uint8_t> y_sorted,
                const CoarseFields* coarse,
                std::span<const Point2f> query,
                std::vector<Slot> slots,
                const SearchOptions& options,
                int num_workers);

  size_t num_slots() const { return slots_.size(); }
  const Slot& slot(size_t s) const { return slots_[s]; }

  // The slot's query rotated by -angle(roll) and quantised, and what the bounds read of it.
  void PrepareSlot(size_t s);
  // PrepareSlot's part for the coarse fields: the slot's histogram, its points' cells and gaps.
  void PrepareSlotCells(size_t s);

  const CellHistogram& histogram(size_t s) const { return histograms_[s]; }

  // The kd-tree over the rolled query, built on first use: slots whose pairs are all pruned
  // never get one.
  const KdTree& QueryTree(size_t s);
  std::span<const PointQ> rolled(size_t s) const { return rolled_[s]; }

  // The rolled query's buckets (query/point_buckets.h), built on first use; unusable for a query
  // with points off the coarse grid (then the kd-tree answers).
  const PointBuckets& QueryBuckets(size_t s);

  // View v's row index from worker `worker`'s cache (RowIndex; a ViewLru, as the buckets and
  // trees).
  const RowIndex& ViewRows(view_id_t v, int worker) {
    return row_caches_[worker].Get(v, [&](RowIndex& rows) { rows.Build(db_.SearchPoints(v)); });
  }

  // View v's buckets from worker `worker`'s cache: like the view kd-trees, a small LRU catches
  // the few rolls of one view that are refined close together.
  const PointBuckets& ViewBuckets(view_id_t v, int worker);

  // max_i |rolled(m.slot)[i] - flip(rolled(base)[i])| (px), rounded up, with flip(T(...)) for a
  // turned member (T(x, y) = (y, -x): roll r + R/4 is roll r turned by T up to the two
  // quantisations): how far the member's rolled query is from the base's, mapped, point by
  // point (both are the query's points in the same order). 0 unless a coordinate sits on a
  // rounding tie.
  double MemberGap(size_t base, const GridMember& m) const;

  // max_i |rolled(member)[i] - map(rolled(base)[i])| in px, rounded up.
  template <typename Map>
  double MappedGap(size_t base, size_t member, Map map) const;

  // The kd-tree over view v's points from worker `worker`'s cache (a small LRU: pairs are
  // visited in increasing bound and the rolls of one view have similar bounds). Only brute force
  // and views beyond the linear scans' coordinate range build them.
  const KdTree& ViewTree(view_id_t v, int worker);

  // Exact D_c of (v, slot s); returns false (abandoned) once it provably exceeds `threshold`.
  // bound_b_px <= B (0 if unknown): A goes first, abandoned as soon as bound_b + a lower bound of
  // A exceeds the threshold, then B, abandoned once A + partial B does.
  bool Score(view_id_t v, size_t s, double threshold, double bound_b_px, int worker, Scored* out);
  // Score's sums of nearest distances, query -> view (A) and view -> query (B); false once a sum
  // provably exceeds `limit`.
  bool SumA(view_id_t v, size_t s, double limit, int worker, double* sum);
  bool SumB(std::span<const PointQ> view, size_t s, double limit, double* sum);

  // The sum of A for (v, s) from exact nearest distances, without a kd-tree (~20-50 us to build
  // for the one or few pairs of a view that are refined): for a view sorted by y, a vectorised
  // scan of the rows within reach of each query point (RowIndex: q's cell's coarse value bounds
  // how far its nearest point can be); otherwise the view's buckets (query/point_buckets.h) or,
  // for points off the coarse grid, a scan of every point. Abandoned as soon as a lower bound of
  // the whole sum exceeds `limit`: it starts at the sum of the points' coarse bounds
  // (CoarseFields::PointLowerBound), often above the limit before any scan, and each scanned point
  // replaces its bound by its exact distance (which is never smaller). Points are scanned in the
  // worker's learnt order (ScanOrder), so the bound rises quickly. A pair that is not
  // abandoned gets the same sum as the kd-tree path, bit for bit: the nearest squared distances are
  // exact integers either way, and they are summed in the query's order.
  bool ScanA(view_id_t v, size_t s, double limit, int worker, double* sum_out);
  // ScanA's scan: each query point's exact nearest squared distance into d2, in the worker's
  // order, raising `bound` (the prior bounds' sum) by each point's gain over its prior; false
  // once it exceeds `stop`.
  bool ScanNearest(view_id_t v,
                   size_t s,
                   int worker,
                   std::span<const uint8_t> prior,
                   double stop,
                   double bound,
                   std::span<int32_t> d2);

  // CoarseFields::PointLowerBound of every point of slot s against view v into out (1/2 px), and
  // their sum: the nine values around each distinct cell once, then per point one byte-wise
  // saturating subtraction of its gaps and a maximum.
  uint64_t PointBounds(view_id_t v, size_t s, int worker, uint8_t* out);

  uint64_t num_view_trees() const { return num_view_trees_.load(); }
  uint64_t num_probe_abandoned() const { return probe_abandoned_.load(); }

 private:
  const Database& db_;
  const SearchOptions& options_;
  std::span<const Point2f> query_;
  std::vector<Point2f> mirrored_;      // the query mirrored (x -> -x), for left-hand slots
  std::span<const int32_t> max_abs_;   // per view: max |x|, |y| (PointQ units)
  std::span<const uint8_t> y_sorted_;  // per view: points sorted by y, all on the coarse grid
  const CoarseFields* coarse_;         // nullptr: no A bound
  std::vector<Slot> slots_;
  std::vector<std::vector<PointQ>> rolled_;
  std::vector<CellHistogram> histograms_;          // per slot, with coarse fields
  std::vector<std::vector<int16_t>> point_cells_;  // per slot: each point's coarse cell or -1
  // Per slot: the cells holding points, each point's eight gaps to the neighbouring cells and
  // its gap to its own (FieldGaps for the fields' kind).
  std::vector<std::vector<uint16_t>> distinct_cells_;
  std::vector<std::vector<uint8_t>> point_gaps_;
  std::vector<std::vector<uint8_t>> point_own_gaps_;
  // Per worker: one view's NeighbourValues by cell, as PointBounds gathered them. Refine visits a
  // view's pairs one after another (its rolls and hands), whose rolled queries share most cells,
  // so each cell of the view is gathered from the cell-major copy once. 30 KB per worker.
  class NeighbourCache {
   public:
    // Makes the cache hold view v's values (forgets the previous view's).
    void Switch(view_id_t v) {
      if (values_.empty()) {
        values_.resize(16 * static_cast<size_t>(CoarseGrid::kCells));
        stamp_.assign(CoarseGrid::kCells, 0);
      }
      if (v == view_ && generation_ != 0) return;
      view_ = v;
      if (++generation_ == 0) {  // wrapped: no stale stamp may equal a generation again
        std::fill(stamp_.begin(), stamp_.end(), 0);
        generation_ = 1;
      }
    }
    bool Has(int cell) const { return stamp_[static_cast<size_t>(cell)] == generation_; }
    // Where cell's nine values go; marks them present.
    uint8_t* Fill(int cell) {
      stamp_[static_cast<size_t>(cell)] = generation_;
      return &values_[16 * static_cast<size_t>(cell)];
    }
    const uint8_t* values(int cell) const { return &values_[16 * static_cast<size_t>(cell)]; }

   private:
    view_id_t view_ = 0;
    uint32_t generation_ = 0;
    std::vector<uint32_t> stamp_;
    std::vector<uint8_t> values_;
  };
  std::vector<NeighbourCache> neighbour_caches_;
  static constexpr size_t kScanSpread = 64;  // points in ScanA's first spread-out pass
  // The order in which ScanA visits the query's points (per worker): the points that have
  // raised the bound most over recent scans first. A query point that no view comes near (an
  // edge of the picture that no rendered hand has) raises every pair's bound, so learning the
  // order drops a pair after fewer points. Any order gives the same result: the bound stays a
  // lower bound, and a pair that is not dropped is summed in the query's order.
  struct ScanOrder {
    static constexpr uint32_t kResortEvery = 64;
    std::vector<uint32_t> index;  // visiting order
    std::vector<float> gain;      // per point: decayed sum of its exact distance less its bound
    uint32_t scans = 0;
    // Starts spread out (every step-th point, then the gaps), so the first scans sample the
    // whole query.
    void Fit(size_t n) {
      if (index.size() == n) return;
      index.clear();
      const size_t step = std::max<size_t>(1, n / kScanSpread);
      for (size_t offset = 0; offset < step; ++offset) {
        for (size_t i = offset; i < n; i += step) index.push_back(static_cast<uint32_t>(i));
      }
      gain.assign(n, 0.0f);
      scans = 0;
    }
    void Done() {
      if (++scans % kResortEvery != 0) return;
      std::stable_sort(
          index.begin(), index.end(), [&](uint32_t a, uint32_t b) { return gain[a] > gain[b]; });
      for (float& g : gain) g *= 0.5f;
    }
  };
  std::vector<ScanOrder> scan_orders_;
  std::vector<std::vector<int32_t>> scan_d2_;     // per worker: ScanA's squared distances
  std::vector<std::vector<uint8_t>> scan_prior_;  // per worker: ScanA's per-point bounds
  std::vector<int32_t> rolled_max_abs_;
  std::atomic<uint64_t> probe_abandoned_{0};
  std::vector<std::unique_ptr<KdTree>> query_trees_;
  std::vector<std::once_flag> query_tree_once_;
  std::vector<PointBuckets> query_buckets_;
  std::vector<std::once_flag> query_buckets_once_;
  // Per worker: the last 2 views' kd-trees, the last 4 views' buckets and row indexes.
  std::vector<ViewLru<std::unique_ptr<KdTree>, 2>> caches_;
  std::vector<ViewLru<PointBuckets, 4>> bucket_caches_;
  std::vector<ViewLru<RowIndex, 4>> row_caches_;
  std::atomic<uint64_t> num_view_trees_{0};
};

}  // namespace handdb::search_internal
