#include "query/searcher.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <optional>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "base/floor_divider.h"
#include "base/progress.h"
#include "base/thread_pool.h"
#include "query/chamfer.h"
#include "query/coarse_bound.h"
#include "query/distance_transform.h"
#include "query/point_buckets.h"
#include "query/view_lru.h"

namespace handdb {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Relative slack on abandonment thresholds so float rounding can never drop a pair that ties
// the k-th best (abandoning is only ever allowed for pairs strictly worse than it).
constexpr double kAbandonSlack = 1e-12;

struct Scored {
  double distance = 0;
  double a = 0;
  double b = 0;
  double lower_bound = 0;
  view_id_t view = 0;
  roll_id_t roll = 0;
  Hand hand = Hand::kRight;
  shape_id_t shape = kInvalidShapeId;  // set by TopK when it limits matches per shape
};

// The total order of results: distance, then view id, then roll, then right before left.
bool Before(const Scored& x, const Scored& y) {
  if (x.distance != y.distance) return x.distance < y.distance;
  if (x.view != y.view) return x.view < y.view;
  if (x.roll != y.roll) return x.roll < y.roll;
  return x.hand == Hand::kRight && y.hand == Hand::kLeft;
}

// Shared top-k under a mutex; threshold() is the k-th best distance (+inf until k are known),
// readable without the lock. With a per-shape limit m > 0 (SearchOptions::max_per_shape) it keeps
// the k best pairs among each shape's m best: a pair whose shape already holds m better pairs is
// refused, a better one replaces that shape's worst; a pair pushed out never returns, since every
// position of the list only improves. Each shape also has its own bound, the m-th best distance
// of its pairs scored so far: a pair above it cannot enter (m better pairs of its shape exist),
// so ThresholdFor(view) = min(k-th best, the view's shape's bound) prunes like threshold() does,
// and far more on the shapes that fill the top of the list (a shape's other rolls and views).
class TopK {
 public:
  // `bound`: pairs above it are never wanted (+inf: every pair may be). `shape_of`: each view's
  // dense shape index (< num_shapes), needed when max_per_shape > 0.
  TopK(size_t k,
       double bound,
       int max_per_shape,
       std::span<const uint32_t> shape_of,
       size_t num_shapes)
      : k_(k),
        max_per_shape_(max_per_shape),
        shape_of_(shape_of),
        shape_best_(max_per_shape > 0 ? num_shapes : 0),
        shape_threshold_(max_per_shape > 0 ? num_shapes : 0),
        threshold_(bound) {
    items_.reserve(k + 1);
    for (std::atomic<double>& t : shape_threshold_) t.store(bound, std::memory_order_relaxed);
  }

  void Insert(Scored s) {
    if (max_per_shape_ > 0) s.shape = shape_of_[s.view];
    if (s.distance > ThresholdFor(s.view)) return;
    std::lock_guard<std::mutex> lock(mu_);
    if (items_.size() == k_ && !Before(s, items_.back())) return;
    // A pair is scored once (ScoreRollBest marks what it scored); kept as a guard.
    for (const Scored& it : items_) {
      if (it.view == s.view && it.roll == s.roll && it.hand == s.hand) return;
    }
    if (max_per_shape_ > 0) {
      // The shape's m best distances so far (of pairs that reached here: the others are above
      // the k-th best, so they would never lower a bound below it).
      std::vector<double>& best = shape_best_[s.shape];
      best.insert(std::upper_bound(best.begin(), best.end(), s.distance), s.distance);
      if (best.size() > static_cast<size_t>(max_per_shape_)) best.pop_back();
      if (best.size() == static_cast<size_t>(max_per_shape_)) {
        shape_threshold_[s.shape].store(best.back(), std::memory_order_relaxed);
      }
      int same = 0;
      size_t worst = 0;
      for (size_t i = 0; i < items_.size(); ++i) {
        if (items_[i].shape == s.shape) {
          ++same;
          worst = i;
        }
      }
      if (same >= max_per_shape_) {
        if (!Before(s, items_[worst])) return;
        items_.erase(items_.begin() + static_cast<std::ptrdiff_t>(worst));
      }
    }
    items_.insert(std::upper_bound(items_.begin(), items_.end(), s, Before), s);
    if (items_.size() > k_) items_.pop_back();
    if (items_.size() == k_) {
      threshold_.store(std::min(threshold_.load(std::memory_order_relaxed), items_.back().distance),
                       std::memory_order_relaxed);
    }
  }
  // The k-th best distance: no pair above it enters.
  double threshold() const { return threshold_.load(std::memory_order_relaxed); }
  // No pair of view v above it enters (threshold() without a per-shape limit).
  double ThresholdFor(view_id_t v) const {
    const double t = threshold();
    if (max_per_shape_ == 0) return t;
    return std::min(t, shape_threshold_[shape_of_[v]].load(std::memory_order_relaxed));
  }
  std::vector<Scored> items() const { return items_; }

 private:
  size_t k_;
  int max_per_shape_;
  std::span<const uint32_t> shape_of_;
  std::mutex mu_;
  std::vector<Scored> items_;
  std::vector<std::vector<double>> shape_best_;
  std::vector<std::atomic<double>> shape_threshold_;
  std::atomic<double> threshold_;
};

// Lower bounds are stored per (view, roll) as uint16 in 1/64 px, rounded down (a lower bound
// stays a lower bound) and saturating at kBoundMax (1023.98 px, still a valid bound); kNoBound
// marks a view without points. Two bytes per virtual view instead of four: on the paper database
// the array is 215 KB, 3.6% of the database.
using Bound = uint16_t;
constexpr Bound kNoBound = 0xFFFF;
constexpr Bound kBoundMax = 0xFFFE;
constexpr double kBoundUnitsPerPx = 64.0;

Bound BoundBelow(double px) {
  const double units = std::floor(std::max(0.0, px) * kBoundUnitsPerPx);
  return static_cast<Bound>(std::min(units, static_cast<double>(kBoundMax)));
}
double BoundPx(Bound b) { return static_cast<double>(b) / kBoundUnitsPerPx; }

// The largest partial sum over n terms that can still give known + sum / n <= threshold, with
// slack so rounding never abandons a pair that ties the threshold; negative: already above.
double Limit(double threshold, double known, double n) {
  if (threshold == kInf) return kInf;
  return (threshold - known) * n * (1 + kAbandonSlack) + kAbandonSlack;
}

// An upper bound (PointQ units) of d(q, Y_v) for q in a cell with coarse value F (1/2 px, rounded
// down, so the true distance is below F + 1/2 px). Boxes: the box's nearest point to Y_v is that
// far, and q is at most the box's diagonal (8 sqrt 2 px, 181.02 units) from it. Centres: q is at
// most half the diagonal (90.51 units) from its cell's centre.
int32_t NearestWithin(FieldKind kind, uint8_t coarse_value) {
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
struct GridMember {
  uint32_t slot = 0;
  GridFlip flip = GridFlip::kNone;
  double gap_px = 0;  // set once the slots are prepared
};

// Per-query state shared by the workers: every slot's rolled query, its coarse histogram and
// the point cells the linear scans read, and (lazily) its kd-tree.
class QueryContext {
 public:
  QueryContext(const Database& db,
               std::span<const int32_t> max_abs,
               std::span<const uint8_t> y_sorted,
               const CoarseFields* coarse,
               std::span<const Point2f> query,
               std::vector<Slot> slots,
               const SearchOptions& options)
      : db_(db),
        options_(options),
        query_(query),
        max_abs_(max_abs),
        y_sorted_(y_sorted),
        coarse_(coarse),
        slots_(std::move(slots)),
        rolled_(slots_.size()),
        histograms_(coarse != nullptr ? slots_.size() : 0),
        point_cells_(coarse != nullptr ? slots_.size() : 0),
        distinct_cells_(coarse != nullptr ? slots_.size() : 0),
        point_gaps_(coarse != nullptr ? slots_.size() : 0),
        point_own_gaps_(coarse != nullptr ? slots_.size() : 0),
        neighbour_caches_(ResolveNumThreads(options.num_threads)),
        scan_orders_(ResolveNumThreads(options.num_threads)),
        scan_d2_(ResolveNumThreads(options.num_threads)),
        scan_prior_(ResolveNumThreads(options.num_threads)),
        rolled_max_abs_(slots_.size()),
        query_trees_(slots_.size()),
        query_tree_once_(slots_.size()),
        query_buckets_(slots_.size()),
        query_buckets_once_(slots_.size()),
        caches_(ResolveNumThreads(options.num_threads)),
        bucket_caches_(ResolveNumThreads(options.num_threads)),
        row_caches_(ResolveNumThreads(options.num_threads)) {
    for (const Slot& s : slots_) {
      if (s.hand == Hand::kLeft && mirrored_.empty()) {
        // x -> -x is exact in float, so the mirrored query of a mirrored view is the view itself.
        mirrored_.assign(query.begin(), query.end());
        for (Point2f& p : mirrored_) p.x = -p.x;
      }
    }
  }

  size_t num_slots() const { return slots_.size(); }
  const Slot& slot(size_t s) const { return slots_[s]; }

  // The slot's query rotated by -angle(roll) and quantised, and what the bounds read of it.
  void PrepareSlot(size_t s) {
    const std::span<const Point2f> source =
        slots_[s].hand == Hand::kLeft ? std::span<const Point2f>(mirrored_) : query_;
    rolled_[s] = RotateAndQuantise(source, -RollAngle(slots_[s].roll, db_.num_rolls()));
    int32_t m = 0;
    for (const PointQ& p : rolled_[s]) {
      m = std::max({m, std::abs(static_cast<int32_t>(p.x)), std::abs(static_cast<int32_t>(p.y))});
    }
    rolled_max_abs_[s] = m;
    if (coarse_ != nullptr) {
      const std::vector<PointQ>& pts = rolled_[s];
      histograms_[s].Build(pts, coarse_->kind());
      point_cells_[s].resize(pts.size());
      // What the scans' per-point bounds read: the distinct cells and each point's gaps to the
      // neighbouring cells and its own (FieldGaps).
      std::vector<uint16_t>& distinct = distinct_cells_[s];
      distinct.clear();
      for (size_t i = 0; i < pts.size(); ++i) {
        const int c = CoarseGrid::CellOf(pts[i]);
        point_cells_[s][i] = static_cast<int16_t>(c);
        if (c >= 0) distinct.push_back(static_cast<uint16_t>(c));
      }
      std::sort(distinct.begin(), distinct.end());
      distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
      point_gaps_[s].resize(8 * pts.size());
      point_own_gaps_[s].resize(pts.size());
      for (size_t i = 0; i < pts.size(); ++i) {
        uint8_t g[9];
        FieldGaps(coarse_->kind(), pts[i], g);
        std::copy(g, g + 8, &point_gaps_[s][8 * i]);
        point_own_gaps_[s][i] = g[8];
      }
    }
  }

  const CellHistogram& histogram(size_t s) const { return histograms_[s]; }

  // The kd-tree over the rolled query, built on first use: slots whose pairs are all pruned
  // never get one.
  const KdTree& QueryTree(size_t s) {
    std::call_once(query_tree_once_[s], [&] {
      query_trees_[s] = std::make_unique<KdTree>(rolled_[s], options_.kdtree);
    });
    return *query_trees_[s];
  }
  std::span<const PointQ> rolled(size_t s) const { return rolled_[s]; }

  // The rolled query's buckets (query/point_buckets.h), built on first use; unusable for a query
  // with points off the coarse grid (then the kd-tree answers).
  const PointBuckets& QueryBuckets(size_t s) {
    std::call_once(query_buckets_once_[s], [&] { query_buckets_[s].Build(rolled_[s]); });
    return query_buckets_[s];
  }

  // View v's row index from worker `worker`'s cache (RowIndex; a ViewLru, as the buckets and
  // trees).
  const RowIndex& ViewRows(view_id_t v, int worker) {
    return row_caches_[worker].Get(v, [&](RowIndex& rows) { rows.Build(db_.SearchPoints(v)); });
  }

  // View v's buckets from worker `worker`'s cache: like the view kd-trees, a small LRU catches
  // the few rolls of one view that are refined close together.
  const PointBuckets& ViewBuckets(view_id_t v, int worker) {
    return bucket_caches_[worker].Get(
        v, [&](PointBuckets& buckets) { buckets.Build(db_.SearchPoints(v)); });
  }

  // max_i |rolled(member)[i] - flip(rolled(base)[i])| (px), rounded up: how far the member's
  // rolled query is from the base's, flipped, point by point (both are the query's points in the
  // same order). 0 unless a coordinate sits on a rounding tie.
  double FlipGap(size_t base, size_t member, GridFlip flip) const {
    const int64_t sx = flip == GridFlip::kX || flip == GridFlip::kXY ? -1 : 1;
    const int64_t sy = flip == GridFlip::kY || flip == GridFlip::kXY ? -1 : 1;
    return MappedGap(base, member, [sx, sy](PointQ p) {
      return std::pair<int64_t, int64_t>{sx * p.x, sy * p.y};
    });
  }

  // The same for the quarter turn T(x, y) = (y, -x): roll r + R/4 is roll r turned by T up to
  // the two quantisations.
  double QuarterTurnGap(size_t base, size_t member) const {
    return MappedGap(base, member, [](PointQ p) {
      return std::pair<int64_t, int64_t>{p.y, -static_cast<int64_t>(p.x)};
    });
  }

  // max_i |rolled(member)[i] - map(rolled(base)[i])| in px, rounded up.
  template <typename Map>
  double MappedGap(size_t base, size_t member, Map map) const {
    const std::vector<PointQ>& a = rolled_[base];
    const std::vector<PointQ>& b = rolled_[member];
    THROW_CHECK_EQ(a.size(), b.size());
    int64_t worst = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      const auto [mx, my] = map(a[i]);
      const int64_t dx = b[i].x - mx;
      const int64_t dy = b[i].y - my;
      worst = std::max(worst, dx * dx + dy * dy);
    }
    return worst == 0 ? 0.0 : std::sqrt(static_cast<double>(worst)) / kPointScale * (1 + 1e-12);
  }

  // The kd-tree over view v's points from worker `worker`'s cache (a small LRU: pairs are
  // visited in increasing bound and the rolls of one view have similar bounds). Only brute force
  // and views beyond the linear scans' coordinate range build them.
  const KdTree& ViewTree(view_id_t v, int worker) {
    return *caches_[worker].Get(v, [&](std::unique_ptr<KdTree>& tree) {
      tree = std::make_unique<KdTree>(db_.SearchPoints(v), options_.kdtree);
      num_view_trees_.fetch_add(1, std::memory_order_relaxed);
    });
  }

  // Exact D_c of (v, slot s); returns false (abandoned) once it provably exceeds `threshold`.
  // bound_b_px <= B (0 if unknown): A goes first, abandoned as soon as bound_b + a lower bound of
  // A exceeds the threshold, then B, abandoned once A + partial B does.
  bool Score(view_id_t v, size_t s, double threshold, double bound_b_px, int worker, Scored* out) {
    const std::span<const PointQ> view = db_.SearchPoints(v);
    const std::span<const PointQ> q = rolled_[s];
    const double nv = static_cast<double>(view.size());
    const double nq = static_cast<double>(q.size());
    bool stopped = false;
    const double limit_a = Limit(threshold, bound_b_px, nq);
    if (limit_a < 0) return false;
    double sum_a = 0;
    // Brute force keeps the kd-trees: it is the reference the scans are tested against.
    if (!options_.brute_force && max_abs_[v] <= kSmallCoordLimit &&
        rolled_max_abs_[s] <= kSmallCoordLimit) {
      if (!ScanA(v, s, limit_a, worker, &sum_a)) {
        probe_abandoned_.fetch_add(1, std::memory_order_relaxed);
        return false;
      }
    } else {
      sum_a = ViewTree(v, worker).SumNearestDistances(q, limit_a, &stopped);
      if (stopped) return false;
    }
    const double a = sum_a / nq;
    const double limit_b = Limit(threshold, a, nv);
    if (limit_b < 0) return false;
    const PointBuckets* buckets = options_.brute_force ? nullptr : &QueryBuckets(s);
    const double sum_b = buckets != nullptr && buckets->usable()
                             ? buckets->SumNearestDistances(view, limit_b, &stopped)
                             : QueryTree(s).SumNearestDistances(view, limit_b, &stopped);
    if (stopped) return false;
    out->a = a;
    out->b = sum_b / nv;
    out->distance = out->a + out->b;
    out->view = v;
    out->roll = slots_[s].roll;
    out->hand = slots_[s].hand;
    return true;
  }

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
  bool ScanA(view_id_t v, size_t s, double limit, int worker, double* sum_out) {
    const std::span<const PointQ> view = db_.SearchPoints(v);
    const std::span<const PointQ> q = rolled_[s];
    std::vector<int32_t>& d2 = scan_d2_[worker];
    d2.resize(q.size());
    const double stop = limit == kInf ? kInf : limit * (1 + 1e-9) + 1e-9;
    const int16_t* cells = coarse_ != nullptr ? point_cells_[s].data() : nullptr;
    // Each point's lower bound from the coarse field around it (CoarseFields::PointLowerBound),
    // in 1/2 px: their sum is already a lower bound of A's sum, often above the limit.
    std::vector<uint8_t>& prior = scan_prior_[worker];
    prior.assign(q.size(), 0);
    double bound = 0;
    if (coarse_ != nullptr) {
      const uint64_t units = PointBounds(v, s, worker, prior.data());
      bound = static_cast<double>(units) / CoarseGrid::kValueUnitsPerPx;
      if (bound > stop) return false;
    }
    // Views sorted by y (every converted view) scan a window of rows; others use buckets.
    const bool window = cells != nullptr && y_sorted_[v] != 0;
    const RowIndex* rows = window ? &ViewRows(v, worker) : nullptr;
    const PointBuckets* buckets = window ? nullptr : &ViewBuckets(v, worker);
    ScanOrder& order = scan_orders_[worker];
    order.Fit(q.size());
    for (size_t j = 0; j < q.size(); ++j) {
      const uint32_t i = order.index[j];
      if (window && cells[i] >= 0) {
        d2[i] = rows->NearestSquared(
            q[i], view, NearestWithin(coarse_->kind(), coarse_->value(v, cells[i])));
      } else if (window) {
        d2[i] = NearestSquaredSmall(q[i], view);
      } else {
        d2[i] = buckets->usable() ? buckets->NearestSquared(q[i]) : NearestSquaredSmall(q[i], view);
      }
      const double gain = std::sqrt(static_cast<double>(d2[i])) / static_cast<double>(kPointScale) -
                          static_cast<double>(prior[i]) / CoarseGrid::kValueUnitsPerPx;
      bound += gain;
      order.gain[i] += static_cast<float>(gain);
      if (bound > stop) {
        order.Done();
        return false;
      }
    }
    order.Done();
    double sum = 0;
    for (size_t i = 0; i < q.size(); ++i) {
      sum += std::sqrt(static_cast<double>(d2[i])) / static_cast<double>(kPointScale);
    }
    if (sum > limit) return false;
    *sum_out = sum;
    return true;
  }

  // CoarseFields::PointLowerBound of every point of slot s against view v into out (1/2 px), and
  // their sum: the nine values around each distinct cell once, then per point one byte-wise
  // saturating subtraction of its gaps and a maximum.
  uint64_t PointBounds(view_id_t v, size_t s, int worker, uint8_t* out) {
    NeighbourCache& cache = neighbour_caches_[worker];
    cache.Switch(v);
    const std::vector<uint16_t>& distinct = distinct_cells_[s];
    for (uint16_t c : distinct) {
      if (!cache.Has(c)) coarse_->PrefetchNeighbours(v, c);
    }
    for (uint16_t c : distinct) {
      if (!cache.Has(c)) coarse_->NeighbourValues(v, c, cache.Fill(c));
    }
    const int16_t* cells = point_cells_[s].data();
    const uint8_t* gaps = point_gaps_[s].data();
    const uint8_t* own_gaps = point_own_gaps_[s].data();
    uint64_t sum = 0;
    for (size_t i = 0; i < point_cells_[s].size(); ++i) {
      if (cells[i] < 0) {
        out[i] = 0;
        continue;
      }
      const uint8_t* values = cache.values(cells[i]);
      int best = std::max(0, values[8] - own_gaps[i]);
#ifdef __SSE2__
      __m128i d = _mm_subs_epu8(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(values)),
                                _mm_loadl_epi64(reinterpret_cast<const __m128i*>(gaps + 8 * i)));
      d = _mm_max_epu8(d, _mm_srli_epi64(d, 32));
      d = _mm_max_epu8(d, _mm_srli_epi64(d, 16));
      d = _mm_max_epu8(d, _mm_srli_epi64(d, 8));
      best = std::max(best, _mm_cvtsi128_si32(d) & 0xFF);
#else
      for (int k = 0; k < 8; ++k) best = std::max(best, values[k] - gaps[8 * i + k]);
#endif
      out[i] = static_cast<uint8_t>(best);
      sum += out[i];
    }
    return sum;
  }

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

}  // namespace

bool SearchOptions::Check() const {
  CHECK_OPTION_GT(top_k, 0);
  CHECK_OPTION_GE(max_per_shape, 0);
  CHECK_OPTION(num_threads == -1 || (num_threads >= 1 && num_threads <= MaxNumThreads()));
  CHECK_OPTION((DistanceGridOptions{dt_cell_px, 170.0f}.Check()));
  CHECK_OPTION_GT(index.candidates, 0);
  CHECK_OPTION(index.nprobe >= 0);
  return true;
}

bool SearcherOptions::Check() const {
  CHECK_OPTION(num_threads == -1 || (num_threads >= 1 && num_threads <= MaxNumThreads()));
  return true;
}

namespace {

// The pool of a Searcher with `num_threads` threads: the calling thread is worker 0, so one
// fewer in the pool, and none for one thread (a search then starts no thread at all).
std::unique_ptr<ThreadPool> StartPool(int num_threads) {
  const int threads = ResolveNumThreads(num_threads);
  return threads > 1 ? std::make_unique<ThreadPool>(threads - 1) : nullptr;
}

}  // namespace

Searcher::Searcher(std::shared_ptr<const Database> db, const SearcherOptions& options)
    : Searcher(std::move(db), options, StartPool(options.num_threads)) {}

Searcher::Searcher(std::shared_ptr<const Database> db,
                   const SearcherOptions& options,
                   std::unique_ptr<ThreadPool> pool)
    : db_(std::move(db)),
      num_threads_(pool != nullptr ? pool->NumThreads() + 1 : 1),
      pool_(std::move(pool)) {
  THROW_CHECK(db_ != nullptr);
  THROW_CHECK(options.Check());
  if (options.few_queries && db_->has_coarse_fields()) exact_field_kind_ = FieldKind::kBox;
  max_abs_.resize(db_->num_views());
  y_sorted_.resize(db_->num_views());
  // Every view's extent and order: read from its points once here, in parallel (on a
  // 10M-virtual-view database ~0.5 GB of mapped points), or from the summaries a database with
  // coded shards made at open.
  constexpr size_t kChunk = 4096;
  const auto& summaries = db_->point_summaries();
  auto summarise = [&](size_t k, int) {
    const size_t end = std::min<size_t>(db_->num_views(), (k + 1) * kChunk);
    for (size_t v = k * kChunk; v < end; ++v) {
      const Database::PointSummary sum =
          db_->coded() ? summaries[v] : Database::Summarise(db_->points(static_cast<view_id_t>(v)));
      max_abs_[v] = sum.max_abs;
      y_sorted_[v] = sum.max_abs < CoarseGrid::kHalfUnits && sum.sorted_by_y;
    }
    return true;
  };
  ParallelFor((db_->num_views() + kChunk - 1) / kChunk, num_threads_, summarise, pool_.get());
  // The grid holds distances to the rolled query, looked up only at view points; its bounds
  // are the same at every node whatever the extent (it grows to contain the query), so the
  // smallest extent that keeps every view on the grid gives identical bounds at the least cost.
  // Views are normalised to lie within 166.3 px of the origin, in practice ~115 px: half the
  // nodes of the 170 px default (docs/query.md).
  const int32_t db_max_abs =
      max_abs_.empty() ? 0 : *std::max_element(max_abs_.begin(), max_abs_.end());
  grid_half_extent_px_ =
      std::clamp(static_cast<float>(db_max_abs) / kPointScale + 1.0f, 8.0f, 2000.0f);
  if (db_->has_coarse_fields()) coarse_rows_ = CoarseFields::RowMajor(*db_);
}

const CoarseFields& Searcher::cell_major_fields() const {
  std::call_once(cell_major_once_, [this] {
    cell_major_ = CoarseFields(*db_, num_threads_, exact_field_kind_, pool_.get());
  });
  return cell_major_;
}

void Searcher::PrepareExactSearch() const {
  cell_major_fields();
  view_histograms();
}

const ViewHistograms& Searcher::view_histograms() const {
  std::call_once(view_histograms_once_,
                 [this] { view_histograms_ = ViewHistograms(*db_, num_threads_, pool_.get()); });
  return view_histograms_;
}

const Searcher::ShapeIndex& Searcher::shape_index() const {
  std::call_once(shape_index_once_, [this] {
    const size_t n = db_->num_views();
    std::vector<shape_id_t> ids(n);
    constexpr size_t kChunk = 4096;
    auto read_shape_ids = [&](size_t c, int) {
      for (size_t v = c * kChunk; v < std::min(n, (c + 1) * kChunk); ++v) {
        ids[v] = db_->label(static_cast<view_id_t>(v)).shape_id;
      }
      return true;
    };
    ParallelFor((n + kChunk - 1) / kChunk, num_threads_, read_shape_ids, pool_.get());
    std::vector<shape_id_t> distinct = ids;
    std::sort(distinct.begin(), distinct.end());
    distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
    shape_index_.of_view.resize(n);
    for (size_t v = 0; v < n; ++v) {
      shape_index_.of_view[v] = static_cast<uint32_t>(
          std::lower_bound(distinct.begin(), distinct.end(), ids[v]) - distinct.begin());
    }
    shape_index_.num_shapes = distinct.size();
  });
  return shape_index_;
}

Searcher::~Searcher() = default;

namespace {

Status CheckSearcherOptions(const SearcherOptions& options) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument,
                  "threads " + std::to_string(options.num_threads) + ": must be -1 or 1.." +
                      std::to_string(MaxNumThreads()) + " (4x the cores, at most 256)");
  }
  return Status::Ok();
}

// The index the options ask for, or null: kAuto attaches the manifest's, kIndexed needs one.
Result<std::shared_ptr<const ViewIndex>> OpenIndex(const Database& db,
                                                   const SearcherOptions& options) {
  if (options.use_index == IndexUse::kExact) return std::shared_ptr<const ViewIndex>();
  if (options.use_index == IndexUse::kAuto && !db.manifest().index) {
    return std::shared_ptr<const ViewIndex>();
  }
  Result<ViewIndex> index = ViewIndex::Open(db.path(), db.manifest());
  if (!index.ok()) return index.status();
  return std::make_shared<const ViewIndex>(std::move(index).value());
}

// The Searcher's pool (none for one thread), or the error of a thread the system refused.
Result<std::unique_ptr<ThreadPool>> CreatePool(int num_threads) {
  const int threads = ResolveNumThreads(num_threads);
  if (threads <= 1) return std::unique_ptr<ThreadPool>();
  return ThreadPool::Create(threads - 1);
}

}  // namespace

Result<std::unique_ptr<Searcher>> Searcher::Open(const std::filesystem::path& dir,
                                                 const SearcherOptions& options) {
  HANDDB_RETURN_IF_ERROR(CheckSearcherOptions(options));
  Result<std::unique_ptr<ThreadPool>> pool = CreatePool(options.num_threads);
  if (!pool.ok()) return pool.status();
  Result<Database> db = Database::Open(
      dir, options.verify, ResolveNumThreads(options.num_threads), pool.value().get());
  if (!db.ok()) return db.status();
  return Make(
      std::make_shared<const Database>(std::move(db).value()), options, std::move(pool).value());
}

Result<std::unique_ptr<Searcher>> Searcher::Create(std::shared_ptr<const Database> db,
                                                   const SearcherOptions& options) {
  THROW_CHECK(db != nullptr);
  HANDDB_RETURN_IF_ERROR(CheckSearcherOptions(options));
  Result<std::unique_ptr<ThreadPool>> pool = CreatePool(options.num_threads);
  if (!pool.ok()) return pool.status();
  return Make(std::move(db), options, std::move(pool).value());
}

Result<std::unique_ptr<Searcher>> Searcher::Make(std::shared_ptr<const Database> db,
                                                 const SearcherOptions& options,
                                                 std::unique_ptr<ThreadPool> pool) {
  Result<std::shared_ptr<const ViewIndex>> index = OpenIndex(*db, options);
  if (!index.ok()) return index.status();
  std::unique_ptr<Searcher> searcher(new Searcher(std::move(db), options, std::move(pool)));
  searcher->SetIndex(std::move(index).value());
  return searcher;
}

SearchMode Searcher::ModeFor(const SearchOptions& options) const {
  if (options.brute_force) return SearchMode::kExact;
  if (options.mode == SearchMode::kAuto) {
    return index_ != nullptr ? SearchMode::kIndexed : SearchMode::kExact;
  }
  return options.mode;
}

namespace {

// The query points must be finite and inside the normalised frame.
Status CheckQuery(std::span<const Point2f> query_px, const SearchOptions& options) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "invalid search options (see the line above)");
  }
  if (query_px.empty()) {
    return Status(StatusCode::kInvalidArgument, "the query has no edge points");
  }
  for (const Point2f& p : query_px) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || std::fabs(p.x) > 2000.0f ||
        std::fabs(p.y) > 2000.0f) {
      return Status(StatusCode::kInvalidArgument,
                    "query point (" + std::to_string(p.x) + ", " + std::to_string(p.y) +
                        ") is not finite or outside +-2000 px of the normalised frame");
    }
  }
  return Status::Ok();
}

// The slots of a search, the first hand's rolls first: right, left, or right then left.
std::vector<Slot> MakeSlots(Hand hand, uint32_t rolls) {
  std::vector<Slot> slots;
  for (Hand h : {Hand::kRight, Hand::kLeft}) {
    if (hand != Hand::kEither && hand != h) continue;
    for (roll_id_t r = 0; r < rolls; ++r) slots.push_back({h, r});
  }
  return slots;
}

// The slots that share one distance grid, the base (kNone) first. With R even, roll r + R/2 is
// roll r turned by 180 degrees (kXY). The left hand's roll r' is the right hand's roll R - r'
// mirrored in x: rot(-a) M X = M rot(a) X with M = diag(-1, 1), and a = -angle(R - r') (kX), and
// its roll R/2 - r is then the right roll r + R/2 mirrored, i.e. roll r reflected in y (kY). So a
// both-hand search builds R/2 grids for its 2R slots (docs/query.md).
std::vector<std::vector<GridMember>> MakeGridGroups(size_t num_slots, uint32_t rolls) {
  const bool halves = rolls >= 2 && rolls % 2 == 0;
  const bool both = num_slots == 2 * static_cast<size_t>(rolls);
  std::vector<std::vector<GridMember>> groups;
  for (uint32_t r = 0; r < (halves ? rolls / 2 : rolls); ++r) {
    std::vector<GridMember> g = {{r, GridFlip::kNone}};
    if (halves) g.push_back({r + rolls / 2, GridFlip::kXY});
    if (both) {
      g.push_back({rolls + (rolls - r) % rolls, GridFlip::kX});
      if (halves) g.push_back({rolls + rolls / 2 - r, GridFlip::kY});
    }
    groups.push_back(std::move(g));
  }
  return groups;
}

// One query's stages, sharing the query context, the top k and the counters: BruteForce(), or
// Bounds() (indexed search: BoundCandidates()) then Refine(); then Matches(). Pairs are indexed
// s * num_views + v over the slots s.
class QueryRun {
 public:
  QueryRun(const Database& db,
           std::span<const int32_t> max_abs,
           std::span<const uint8_t> y_sorted,
           float grid_half_extent_px,
           const CoarseFields* coarse,
           const ViewHistograms* view_histograms,
           std::span<const Point2f> query_px,
           const SearchOptions& options,
           int threads,
           ThreadPool* pool,
           std::chrono::steady_clock::time_point progress_since,
           std::span<const uint32_t> shape_of,
           size_t num_shapes)
      : db_(db),
        max_abs_(max_abs),
        grid_half_extent_px_(grid_half_extent_px),
        coarse_(coarse),
        view_histograms_(coarse != nullptr ? view_histograms : nullptr),
        options_(options),
        threads_(threads),
        pool_(pool),
        num_views_(db.num_views()),
        num_rolls_(db.num_rolls()),
        k_(static_cast<size_t>(options.top_k)),
        ctx_(db,
             max_abs,
             y_sorted,
             coarse,
             query_px,
             MakeSlots(options.hand, db.num_rolls()),
             options),
        shape_of_(options.max_per_shape > 0 ? shape_of : std::span<const uint32_t>()),
        num_shapes_(num_shapes),
        top_(k_, kInf, options.max_per_shape, shape_of, num_shapes),
        progress_since_(progress_since) {}

  size_t num_slots() const { return ctx_.num_slots(); }

  // The reference: exact D_c for every (view, slot).
  void BruteForce(SearchStats* stats, std::chrono::steady_clock::time_point start) {
    ParallelFor(
        num_slots(),
        threads_,
        [&](size_t s, int) {
          ctx_.PrepareSlot(s);
          return true;
        },
        pool_);
    stats->seconds_bounds = SecondsSince(start);
    const auto refine_start = std::chrono::steady_clock::now();
    const auto progress = MakeProgress("brute force", num_views_ * num_slots(), "pairs");
    ParallelFor(
        num_views_,
        threads_,
        [&](size_t v, int worker) {
          if (db_.point_count(static_cast<view_id_t>(v)) != 0) {
            for (size_t s = 0; s < num_slots(); ++s) {
              Scored sc;
              ctx_.Score(static_cast<view_id_t>(v), s, kInf, 0.0, worker, &sc);
              top_.Insert(sc);
            }
            refined_.fetch_add(num_slots(), std::memory_order_relaxed);
          }
          progress->Add(num_slots());
          return true;
        },
        pool_);
    stats->seconds_refine = SecondsSince(refine_start);
  }

  // Step 1: lower bounds of every pair, L = L_A + L_B (docs/query.md).
  //  a. Every slot's rolled query, coarse histogram and coarse field.
  //  b. The cell-only L_A of every pair: per block of views, one streaming product per slot
  //     (CoarseFields); and the coarse B bound L_Bc of the same views, one product per view for
  //     all slots (ViewHistograms), into lb_.
  //  c. The threshold seeded: the pairs with the smallest L_A + L_Bc scored exactly, so that it
  //     is near the final k-th best before any distance grid is built. Then L_A with the
  //     neighbour terms, only for the groups of 32 views that hold a pair still at or below it.
  //  d. Per grid group (up to four slots sharing one distance transform), most promising first:
  //     L_B for the pairs whose L_A + L_Bc is still <= the k-th best, stopped as soon as L_A +
  //     L_B exceeds it (lb_ keeps the larger of L_Bc and L_B), then each slot's best two pairs
  //     scored. A group with no such pair builds no grid.
  void Bounds() {
    const size_t n = num_views_ * num_slots();
    la_.assign(n, 0);
    lb_.assign(n, 0);
    slot_begin_.resize(num_slots() + 1);
    for (size_t s = 0; s <= num_slots(); ++s) slot_begin_[s] = s * num_views_;
    ParallelFor(
        num_slots(),
        threads_,
        [&](size_t s, int) {
          ctx_.PrepareSlot(s);
          return true;
        },
        pool_);
    MakeQueryDividers();
    if (view_histograms_ != nullptr) PrepareSlotFields();
    CoarseBounds();
    if (coarse_ != nullptr) {
      Seed();
      NeighbourBounds();
    }
    FineBounds();
  }

  // Step 1 of indexed search (SearchMode::kIndexed): Bounds() over the candidate pairs only
  // (s * num_views + v, any order, repeats allowed), each an entry of la_ / lb_ in increasing
  // pair order: the slots of the grid groups holding candidates prepared, L_A per pair (the same
  // exact integer sum as the streaming product, so the same bound), the threshold seeded from
  // them, then L_B from the groups' grids (no L_Bc: measured no faster on a few thousand
  // candidates, docs/query.md). Refine() then gives the exact top-k among the candidates; with
  // every pair a candidate, exactly the result of Bounds() and Refine().
  void BoundCandidates(std::vector<uint32_t> pairs) {
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    pairs_ = std::move(pairs);
    la_.assign(pairs_.size(), 0);
    lb_.assign(pairs_.size(), 0);
    slot_begin_.assign(num_slots() + 1, 0);
    for (uint32_t p : pairs_) ++slot_begin_[p / num_views_ + 1];
    for (size_t s = 0; s < num_slots(); ++s) slot_begin_[s + 1] += slot_begin_[s];
    // Every slot of a group holding a candidate: FineBounds builds the grid from the group's base
    // and measures each member's gap to it.
    std::vector<size_t> prepare;
    for (const std::vector<GridMember>& group : MakeGridGroups(num_slots(), num_rolls_)) {
      if (GroupEntries(group) == 0) continue;
      for (const GridMember& m : group) prepare.push_back(m.slot);
    }
    ParallelFor(
        prepare.size(),
        threads_,
        [&](size_t j, int) {
          ctx_.PrepareSlot(prepare[j]);
          return true;
        },
        pool_);
    MakeQueryDividers();
    ParallelFor(
        pairs_.size(),
        threads_,
        [&](size_t e, int) {
          la_[e] = PairCoarseBound(pairs_[e] % num_views_, pairs_[e] / num_views_);
          return true;
        },
        pool_);
    if (coarse_ != nullptr) Seed();
    FineBounds();
  }

  // Step 2: visit pairs in increasing bound. First the k smallest bounds give a threshold,
  // then only pairs whose bound is <= it are sorted and visited.
  void Refine() {
    const size_t n = la_.size();
    auto by_bound = [&](uint32_t x, uint32_t y) { return ByBound(x, y); };
    const std::vector<uint32_t> first = SmallestPairs(0, n, k_, by_bound);
    Visit(first);
    std::vector<uint32_t> rest;
    const uint32_t last_first = first.empty() ? 0 : first.back();
    for (uint32_t i = 0; i < n; ++i) {
      if (la_[i] != kNoBound && TotalPx(i) <= ThresholdFor(i) &&
          (first.empty() || by_bound(last_first, i))) {
        rest.push_back(i);
      }
    }
    // `rest` bounds the pairs to refine. They are visited one view at a time (its pairs in
    // increasing bound, the views by their smallest bound): the pairs of one view read the same
    // points, row index and coarse-field cache lines, and the seeded k-th best is already near
    // its final value, so visiting by view refines about the same pairs as visiting by bound.
    const auto progress = MakeProgress("refine", rest.size(), "pairs");
    VisitByView(std::move(rest), progress.get());
    progress->SetTotal(progress->done());
  }

  // The top k, best first, with labels rolled (and mirrored back for the left hand) and shape
  // names.
  std::vector<Match> Matches() const {
    std::vector<Match> matches;
    for (const Scored& s : top_.items()) {
      Match m;
      m.view_id = s.view;
      m.roll = s.roll;
      m.roll_angle = RollAngle(s.roll, num_rolls_);
      m.distance = s.distance;
      m.a = s.a;
      m.b = s.b;
      m.lower_bound = s.lower_bound;
      m.label = RollLabel(db_.label(s.view), m.roll_angle);
      if (s.hand == Hand::kLeft) m.label = MirrorLabel(m.label);
      m.hand = s.hand;
      m.shape_name = std::string(db_.shape_name(m.label.shape_id));
      matches.push_back(std::move(m));
    }
    return matches;
  }

  void AddInto(SearchStats* stats) const {
    stats->bounded += la_.size();
    stats->grids += grids_.load();
    stats->grid_bounded += grid_bounded_.load();
    stats->refined += refined_.load();
    stats->abandoned += abandoned_.load();
    stats->view_trees += ctx_.num_view_trees();
    stats->probe_abandoned += ctx_.num_probe_abandoned();
  }

 private:
  double TotalPx(size_t i) const { return BoundPx(la_[i]) + BoundPx(lb_[i]); }

  // The pair (s * num_views + v) of entry e of la_ / lb_: e itself in exact search.
  size_t PairOf(size_t e) const { return pairs_.empty() ? e : pairs_[e]; }
  size_t SlotEntries(size_t s) const { return slot_begin_[s + 1] - slot_begin_[s]; }
  size_t GroupEntries(const std::vector<GridMember>& group) const {
    size_t n = 0;
    for (const GridMember& m : group) n += SlotEntries(m.slot);
    return n;
  }

  // L_A of a slot from its exact integer sum (1/2 px): floor(64 sum / 2 / |Q_s|).
  Bound CoarseABound(uint64_t sum, size_t s) const {
    const uint64_t units = query_divider_[s](sum * static_cast<uint64_t>(kBoundUnitsPerPx / 2));
    return static_cast<Bound>(std::min<uint64_t>(units, kBoundMax));
  }

  // Every prepared slot's divider by its point count (CoarseABound), after PrepareSlot.
  void MakeQueryDividers() {
    query_divider_.clear();
    for (size_t s = 0; s < num_slots(); ++s) {
      query_divider_.emplace_back(std::max<uint64_t>(1, ctx_.rolled(s).size()));
    }
  }

  // L_A of one pair as CoarseBounds() computes it (kNoBound for a view without points, 0 without
  // coarse fields): sum_c n(c) F_v(c) is the same exact integer as the streaming product's.
  Bound PairCoarseBound(size_t v, size_t s) const {
    if (db_.point_count(static_cast<view_id_t>(v)) == 0) return kNoBound;
    if (coarse_ == nullptr) return 0;
    return CoarseABound(coarse_->PairSum(ctx_.histogram(s), v), s);
  }

  // L_A of every pair into la_ (kNoBound for views without points), or 0 without coarse fields.
  // L_A = sum / 2 / |Q| px with an exact integer sum, so floor(64 L_A) is an integer division.
  void CoarseBounds() {
    if (coarse_ == nullptr) {
      for (size_t s = 0; s < num_slots(); ++s) {
        for (view_id_t v = 0; v < num_views_; ++v) {
          if (db_.point_count(v) == 0) la_[s * num_views_ + v] = kNoBound;
        }
      }
      return;
    }
    ForEachViewBlock([&](size_t b, size_t v0, size_t v1, uint32_t* sums) {
      for (size_t s = 0; s < num_slots(); ++s) {
        coarse_->BlockSums(ctx_.histogram(s), b, sums, /*neighbours=*/false);
        for (size_t v = v0; v < v1; ++v) {
          la_[s * num_views_ + v] = db_.point_count(static_cast<view_id_t>(v)) == 0
                                        ? kNoBound
                                        : CoarseABound(sums[v - v0], s);
        }
      }
      if (view_histograms_ != nullptr) CoarseBBounds(v0, v1);
    });
  }

  // fn(block, v0, v1, sums) for every block of views [v0, v1) of the coarse fields, in
  // parallel, with a scratch array of kBlock sums.
  template <typename Fn>
  void ForEachViewBlock(Fn fn) {
    ParallelFor(
        coarse_->num_blocks(),
        threads_,
        [&](size_t b, int) {
          std::array<uint32_t, CoarseFields::kBlock> sums;
          const size_t v0 = b * CoarseFields::kBlock;
          fn(b, v0, std::min(num_views_, v0 + CoarseFields::kBlock), sums.data());
          return true;
        },
        pool_);
  }

  // L_A with the neighbour terms for the groups of 32 views of each block and slot that hold a
  // pair still at or below the k-th best after the seed; the others keep the cell-only L_A of
  // CoarseBounds (a smaller bound, and their pairs are already above the k-th best, which only
  // falls). On real photos ~70-90% of the groups are skipped.
  void NeighbourBounds() {
    ForEachViewBlock([&](size_t b, size_t v0, size_t v1, uint32_t* sums) {
      for (size_t s = 0; s < num_slots(); ++s) {
        const double threshold = top_.threshold();
        unsigned groups = 0;
        for (size_t v = v0; v < v1; ++v) {
          const size_t e = s * num_views_ + v;
          if (la_[e] == kNoBound) continue;
          const double t =
              shape_of_.empty() ? threshold : top_.ThresholdFor(static_cast<view_id_t>(v));
          if (TotalPx(e) <= t) groups |= 1u << ((v - v0) / 32);
        }
        if (groups == 0) continue;
        coarse_->BlockSums(ctx_.histogram(s), b, sums, /*neighbours=*/true, groups);
        for (size_t v = v0; v < v1; ++v) {
          const size_t e = s * num_views_ + v;
          if (la_[e] == kNoBound || (groups >> ((v - v0) / 32) & 1) == 0) continue;
          la_[e] = std::max(la_[e], CoarseABound(sums[v - v0], s));
        }
      }
    });
  }

  // Every slot's coarse field (SlotFields), one ComputeCoarseField per R/4 rolls: with R a
  // multiple of 4 the grid groups' bases are rolls r < R/2 of the right hand (or of the one
  // hand searched), and base r + R/4 is base r quarter-turned (CopyQuarterTurned); each group's
  // members are its base flipped (CopyFlipped). Every copy subtracts its measured gap.
  void PrepareSlotFields() {
    const std::vector<std::vector<GridMember>> groups = MakeGridGroups(num_slots(), num_rolls_);
    slot_fields_.Reset(num_slots());
    const size_t quarter = num_rolls_ % 4 == 0 ? num_rolls_ / 4 : 0;
    const size_t computed = quarter > 0 ? quarter : groups.size();
    ParallelFor(
        computed,
        threads_,
        [&](size_t g, int) {
          const size_t base = groups[g][0].slot;
          slot_fields_.Compute(base, ctx_.rolled(base));
          CopyMembers(groups[g]);
          if (quarter > 0) {
            const size_t turned = groups[g + quarter][0].slot;
            slot_fields_.CopyQuarterTurned(base, turned, ctx_.QuarterTurnGap(base, turned));
            CopyMembers(groups[g + quarter]);
          }
          return true;
        },
        pool_);
  }

  // The fields of a grid group's members from its base's: flipped, less their gaps.
  void CopyMembers(const std::vector<GridMember>& group) {
    const size_t base = group[0].slot;
    for (size_t i = 1; i < group.size(); ++i) {
      const GridMember& m = group[i];
      slot_fields_.CopyFlipped(base, m.slot, m.flip, ctx_.FlipGap(base, m.slot, m.flip));
    }
  }

  // L_Bc from its exact integer sum (1/2 px) for a view: floor(64 sum / 2 / |Y_v|), `ny` dividing
  // by |Y_v|.
  static Bound CoarseBBound(uint64_t sum, const FloorDivider& ny) {
    const uint64_t units = ny(sum * static_cast<uint64_t>(kBoundUnitsPerPx / 2));
    return static_cast<Bound>(std::min<uint64_t>(units, kBoundMax));
  }

  // L_Bc of views [v0, v1) for every slot into lb_: sum_c n_v(c) G_s(c) / 2 / |Y_v| px, an exact
  // integer sum, so floor(64 L_Bc) is an integer division (coarse_bound.h).
  void CoarseBBounds(size_t v0, size_t v1) {
    thread_local std::vector<uint32_t> sums;
    sums.resize(slot_fields_.stride());
    for (size_t v = v0; v < v1; ++v) {
      const size_t ny = db_.point_count(static_cast<view_id_t>(v));
      if (ny == 0) continue;
      view_histograms_->Sums(v, slot_fields_, sums.data());
      const FloorDivider divider(ny);
      for (size_t s = 0; s < num_slots(); ++s) {
        lb_[s * num_views_ + v] = CoarseBBound(sums[s], divider);
      }
    }
  }

  // No pair i above it can enter the top k (the k-th best, or its view's shape's bound).
  double ThresholdFor(uint32_t i) const {
    if (shape_of_.empty()) return top_.threshold();
    return top_.ThresholdFor(static_cast<view_id_t>(PairOf(i) % num_views_));
  }

  // Pairs by their bound L_A + L_B, then by index.
  bool ByBound(uint32_t x, uint32_t y) const {
    const uint32_t tx = static_cast<uint32_t>(la_[x]) + lb_[x];
    const uint32_t ty = static_cast<uint32_t>(la_[y]) + lb_[y];
    return tx != ty ? tx < ty : x < y;
  }

  // The (at most) m pairs of [begin, end) not yet scored that come first under `less`, sorted by
  // it: a bounded max-heap, no range-sized index array.
  template <typename Less>
  std::vector<uint32_t> SmallestPairs(size_t begin, size_t end, size_t m, Less less) const {
    std::vector<uint32_t> best;
    best.reserve(m + 1);
    for (uint32_t i = static_cast<uint32_t>(begin); i < end; ++i) {
      if (la_[i] == kNoBound) continue;
      if (best.size() < m) {
        best.push_back(i);
        std::push_heap(best.begin(), best.end(), less);
      } else if (m > 0 && less(i, best.front())) {
        std::pop_heap(best.begin(), best.end(), less);
        best.back() = i;
        std::push_heap(best.begin(), best.end(), less);
      }
    }
    std::sort(best.begin(), best.end(), less);
    return best;
  }

  // Scores the pairs with the smallest L_A (a few times k), best first, and marks them scored.
  // With a per-shape limit also each shape's pair of smallest L_A: the seed's pairs are mostly
  // one shape's rolls and views, which would leave the k-th best shape, the bound of every shape
  // not yet scored, at +inf.
  void Seed() {
    auto less = [&](uint32_t x, uint32_t y) { return ByBound(x, y); };
    std::vector<uint32_t> best = SmallestPairs(0, la_.size(), 2 * k_ + 8, less);
    if (!shape_of_.empty()) {
      std::vector<uint32_t> per_shape(num_shapes_, UINT32_MAX);
      for (uint32_t i = 0; i < la_.size(); ++i) {
        if (la_[i] == kNoBound) continue;
        uint32_t& b = per_shape[shape_of_[PairOf(i) % num_views_]];
        if (b == UINT32_MAX || less(i, b)) b = i;
      }
      for (uint32_t i : per_shape) {
        if (i != UINT32_MAX) best.push_back(i);
      }
      std::sort(best.begin(), best.end(), less);
      best.erase(std::unique(best.begin(), best.end()), best.end());
    }
    ParallelFor(
        best.size(),
        threads_,
        [&](size_t j, int worker) {
          ScorePair(best[j], worker);
          return true;
        },
        pool_);
  }

  void FineBounds() {
    auto groups = MakeGridGroups(num_slots(), num_rolls_);
    // Each group's smallest L_A, to visit the most promising grids first. A group without
    // entries (indexed search: no candidate in its slots) builds no grid.
    std::vector<std::pair<Bound, size_t>> order;
    for (size_t g = 0; g < groups.size(); ++g) {
      if (GroupEntries(groups[g]) == 0) continue;
      Bound best = kNoBound;
      for (GridMember& m : groups[g]) {
        m.gap_px = ctx_.FlipGap(groups[g][0].slot, m.slot, m.flip);
        if (SlotEntries(m.slot) == 0) continue;
        for (size_t e = slot_begin_[m.slot]; e < slot_begin_[m.slot + 1]; ++e) {
          if (la_[e] == kNoBound) continue;
          best = static_cast<Bound>(
              std::min<uint32_t>(best, std::min<uint32_t>(kNoBound - 1, la_[e] + lb_[e])));
        }
      }
      order.emplace_back(best, g);
    }
    std::sort(order.begin(), order.end());
    const DistanceGridOptions grid_options{options_.dt_cell_px, grid_half_extent_px_};
    std::vector<DistanceGrid> grids(threads_, DistanceGrid(grid_options));
    size_t progress_slots = 0;
    for (const auto& entry : order) progress_slots += groups[entry.second].size();
    const auto progress = MakeProgress("bounds", progress_slots, "rolls");
    ParallelFor(
        order.size(),
        threads_,
        [&](size_t i, int worker) {
          const std::vector<GridMember>& group = groups[order[i].second];
          if (BoundPx(order[i].first) <= top_.threshold()) {
            DistanceGrid& grid = grids[worker];
            grid.Build(ctx_.rolled(group[0].slot));
            grids_.fetch_add(1, std::memory_order_relaxed);
            for (const GridMember& m : group) {
              BoundSlot(grid, m);
              ScoreSlotBest(m.slot, worker);
            }
          }
          progress->Add(group.size());
          return true;
        },
        pool_);
  }

  // L_B into lb_ for every pair of the member's slot whose L_A is <= the k-th best, from the
  // group's grid read through the member's flip, minus its gap.
  void BoundSlot(const DistanceGrid& grid, const GridMember& m) {
    constexpr size_t kChunk = 64;
    uint64_t bounded = 0;
    for (size_t e = slot_begin_[m.slot]; e < slot_begin_[m.slot + 1]; ++e) {
      const Bound la = la_[e];
      if (la == kNoBound) continue;
      const auto v = static_cast<view_id_t>(PairOf(e) % num_views_);
      const double threshold = top_.ThresholdFor(v);
      if (TotalPx(e) > threshold) continue;
      const std::span<const PointQ> pts = db_.SearchPoints(v);
      const double n = static_cast<double>(pts.size());
      const double limit = Limit(threshold, BoundPx(la), n) + m.gap_px * n;
      const bool fast = grid.Covers(max_abs_[v]);
      double sum = 0;
      for (size_t i = 0; i < pts.size() && sum <= limit; i += kChunk) {
        const auto chunk = pts.subspan(i, std::min(kChunk, pts.size() - i));
        sum += fast ? grid.SumLowerBoundsFast(chunk, m.flip) : grid.SumLowerBounds(chunk, m.flip);
      }
      const double mean = sum / n;
      lb_[e] = std::max(
          lb_[e],
          BoundBelow(mean - DistanceGrid::MeanLowerBoundMargin(pts.size(), mean) - m.gap_px));
      ++bounded;
    }
    grid_bounded_.fetch_add(bounded, std::memory_order_relaxed);
  }

  // Scores this slot's most promising pairs now so later groups can stop early (k pairs while
  // fewer than k are known, then 2).
  void ScoreSlotBest(size_t s, int worker) {
    const size_t m = std::min<size_t>(SlotEntries(s), top_.threshold() == kInf ? k_ : 2);
    auto by_bound = [&](uint32_t x, uint32_t y) { return ByBound(x, y); };
    for (uint32_t i : SmallestPairs(slot_begin_[s], slot_begin_[s + 1], m, by_bound)) {
      ScorePair(i, worker);
    }
  }

  // Scores pair i unless its bound is above the k-th best, and marks it scored (kNoBound), so
  // that Refine does not score it again (its D_c is in the top k already, or was above the
  // threshold, which only falls).
  void ScorePair(uint32_t i, int worker) {
    const double threshold = ThresholdFor(i);
    if (TotalPx(i) > threshold) return;
    ScoreVisited(i, threshold, worker);
    la_[i] = kNoBound;
  }

  // Scores the pairs of `order` (increasing bound) until a bound exceeds the k-th best.
  void Visit(std::span<const uint32_t> order) {
    ParallelFor(
        order.size(),
        threads_,
        [&](size_t j, int worker) {
          const uint32_t i = order[j];
          if (TotalPx(i) > top_.threshold()) return false;  // every later pair: a larger bound
          const double threshold = ThresholdFor(i);
          if (TotalPx(i) > threshold) return true;  // above its shape's bound
          ScoreVisited(i, threshold, worker);
          return true;
        },
        pool_);
  }

  // Scores the pairs of `pairs` whose bound is at or below the k-th best when they are reached,
  // one view at a time (Refine).
  void VisitByView(std::vector<uint32_t> pairs, Progress* progress) {
    auto view_of = [&](uint32_t i) { return PairOf(i) % num_views_; };
    std::sort(pairs.begin(), pairs.end(), [&](uint32_t x, uint32_t y) {
      const size_t vx = view_of(x);
      const size_t vy = view_of(y);
      return vx != vy ? vx < vy : ByBound(x, y);
    });
    // Each view's run of pairs, by the bound of its first (smallest) pair.
    std::vector<std::pair<uint32_t, uint32_t>> runs;  // [begin, end) in `pairs`
    for (size_t b = 0; b < pairs.size();) {
      size_t e = b + 1;
      while (e < pairs.size() && view_of(pairs[e]) == view_of(pairs[b])) ++e;
      runs.emplace_back(static_cast<uint32_t>(b), static_cast<uint32_t>(e));
      b = e;
    }
    std::sort(runs.begin(), runs.end(), [&](const auto& x, const auto& y) {
      return ByBound(pairs[x.first], pairs[y.first]);
    });
    ParallelFor(
        runs.size(),
        threads_,
        [&](size_t r, int worker) {
          for (uint32_t j = runs[r].first; j < runs[r].second; ++j) {
            const uint32_t i = pairs[j];
            const double threshold = ThresholdFor(i);
            if (TotalPx(i) > threshold) break;  // the view's later pairs: larger bounds
            if (progress != nullptr) progress->Add();
            ScoreVisited(i, threshold, worker);
          }
          return true;
        },
        pool_);
  }

  // Scores pair i, visited with the k-th best at `threshold`, into the top k.
  void ScoreVisited(uint32_t i, double threshold, int worker) {
    const auto v = static_cast<view_id_t>(PairOf(i) % num_views_);
    const size_t s = PairOf(i) / num_views_;
    refined_.fetch_add(1, std::memory_order_relaxed);
    Scored sc;
    if (ctx_.Score(v, s, threshold, BoundPx(lb_[i]), worker, &sc)) {
      sc.lower_bound = TotalPx(i);
      top_.Insert(sc);
    } else {
      abandoned_.fetch_add(1, std::memory_order_relaxed);
    }
  }

  // One phase's progress line (SearchOptions::progress), e.g. "query refine (both hands)".
  std::unique_ptr<Progress> MakeProgress(const std::string& phase,
                                         uint64_t total,
                                         const char* unit) const {
    std::string label = "query " + phase;
    if (options_.hand == Hand::kEither) label += " (both hands)";
    auto progress = std::make_unique<Progress>(label, total, options_.progress, unit);
    progress->QuietUnlessSlow(progress_since_);
    return progress;
  }

  const Database& db_;
  std::span<const int32_t> max_abs_;
  float grid_half_extent_px_;
  const CoarseFields* coarse_;
  const ViewHistograms* view_histograms_;  // nullptr: no coarse B bound
  SlotFields slot_fields_;
  const SearchOptions& options_;
  const int threads_;
  ThreadPool* const pool_;
  const size_t num_views_;
  const uint32_t num_rolls_;
  const size_t k_;
  QueryContext ctx_;
  std::span<const uint32_t> shape_of_;  // per view: dense shape index (empty: no per-shape limit)
  size_t num_shapes_;
  TopK top_;
  // Per pair (indexed search: per candidate pair, pairs_): L_A (kNoBound: a view without points,
  // or a pair already scored) and L_B (0 until computed), both rounded down to 1/64 px;
  // L = L_A + L_B <= D_c.
  std::vector<Bound> la_;
  std::vector<Bound> lb_;
  std::vector<FloorDivider> query_divider_;  // per slot: by its rolled query's point count
  // Indexed search: each entry's pair (s * num_views + v), increasing; empty in exact search,
  // where entry i is pair i. The entries of slot s are [slot_begin_[s], slot_begin_[s + 1]).
  std::vector<uint32_t> pairs_;
  std::vector<size_t> slot_begin_;
  std::atomic<uint64_t> grids_{0};
  std::atomic<uint64_t> grid_bounded_{0};
  std::atomic<uint64_t> refined_{0};
  std::atomic<uint64_t> abandoned_{0};
  const std::chrono::steady_clock::time_point progress_since_;
};

}  // namespace

std::string_view SearchModeName(SearchMode mode) {
  switch (mode) {
    case SearchMode::kAuto:
      return "auto";
    case SearchMode::kExact:
      return "exact";
    case SearchMode::kIndexed:
      return "indexed";
  }
  return "?";
}

std::string_view IndexUseName(IndexUse use) {
  switch (use) {
    case IndexUse::kAuto:
      return "auto";
    case IndexUse::kExact:
      return "exact";
    case IndexUse::kIndexed:
      return "indexed";
  }
  return "?";
}

Result<IndexUse> ParseIndexUse(std::string_view name) {
  for (IndexUse u : {IndexUse::kAuto, IndexUse::kExact, IndexUse::kIndexed}) {
    if (name == IndexUseName(u)) return u;
  }
  return Status(StatusCode::kInvalidArgument,
                "unknown search '" + std::string(name) + "' (auto, exact or indexed)");
}

std::string_view HandName(Hand hand) {
  switch (hand) {
    case Hand::kRight:
      return "right";
    case Hand::kLeft:
      return "left";
    case Hand::kEither:
      return "either";
  }
  return "?";
}

Result<Hand> ParseHand(std::string_view name) {
  for (Hand h : {Hand::kRight, Hand::kLeft, Hand::kEither}) {
    if (name == HandName(h)) return h;
  }
  return Status(StatusCode::kInvalidArgument,
                "unknown hand '" + std::string(name) + "' (right, left or either)");
}

ViewLabel MirrorLabel(const ViewLabel& label) {
  ViewLabel out = label;
  for (auto& kp : out.keypoints) kp[0] = -kp[0];
  out.camera_roll = -label.camera_roll;
  out.view_direction[1] = -label.view_direction[1];
  out.view_phi = -label.view_phi;
  return out;
}

Result<std::vector<Match>> Searcher::Search(std::span<const Point2f> query_px,
                                            const SearchOptions& options,
                                            SearchStats* stats) const {
  try {
    return SearchImpl(query_px, options, stats);
  } catch (const CodedViewError& e) {
    // A coded view that does not decode (query/database.h): the search's error, not a crash.
    return Status(e.status().code(),
                  e.status().message() + " (run 'handdb validate " + db_->path().string() +
                      "' for every problem)");
  }
}

Result<std::vector<Match>> Searcher::SearchImpl(std::span<const Point2f> query_px,
                                                const SearchOptions& options,
                                                SearchStats* stats) const {
  const auto start = std::chrono::steady_clock::now();
  if (Status s = CheckQuery(query_px, options); !s.ok()) return s;
  const bool indexed = ModeFor(options) == SearchMode::kIndexed;
  if (indexed) {
    if (index_ == nullptr) {
      return Status(StatusCode::kInvalidArgument,
                    db_->path().string() +
                        ": indexed search needs an index (build one: handdb index " +
                        db_->path().string() + ")");
    }
    if (index_->num_views() != db_->num_views() || index_->num_rolls() != db_->num_rolls()) {
      return Status(StatusCode::kSizeMismatch,
                    db_->path().string() + ": the index is of another database");
    }
  }

  // A coded database's views decoded for this search stay valid until it returns (the pin);
  // then the searches' cache is trimmed if it outgrew its budget (query/database.h).
  struct TrimAfter {
    const Database& db;
    ~TrimAfter() { db.TrimSearchCache(); }
  } trim_after{*db_};
  const Database::SearchPin pin(*db_);
  // The Searcher's pool, capped by the options; the calling thread is worker 0.
  const int threads = std::min(ResolveNumThreads(options.num_threads), num_threads_);
  ThreadPool* pool = threads > 1 ? pool_.get() : nullptr;
  const auto progress_since = options.progress_since == std::chrono::steady_clock::time_point{}
                                  ? start
                                  : options.progress_since;
  SearchStats local;
  local.virtual_views = db_->num_virtual_views();
  local.query_points = query_px.size();
  local.searches = options.hand == Hand::kEither ? 2 : 1;
  local.mode = indexed ? SearchMode::kIndexed : SearchMode::kExact;

  // The coarse fields the bounds read: none for brute force (it scores every pair with the
  // kd-trees), the shards' own for indexed search when they have them, else the cell-major copy.
  const CoarseFields* fields = nullptr;
  if (options.coarse_bound && !options.brute_force && db_->num_views() > 0) {
    fields = indexed && !coarse_rows_.empty() ? &coarse_rows_ : &cell_major_fields();
  }
  const ShapeIndex* shapes = options.max_per_shape > 0 ? &shape_index() : nullptr;
  // Hand::kEither searches both hands' slots in one run with one top k, ordered by (D_c, view
  // id, roll, right before left): exactly the merge of the two brute-force searches.
  QueryRun run(
      *db_,
      max_abs_,
      y_sorted_,
      grid_half_extent_px_,
      fields,
      fields != nullptr && !indexed ? &view_histograms() : nullptr,
      query_px,
      options,
      threads,
      pool,
      progress_since,
      shapes != nullptr ? std::span<const uint32_t>(shapes->of_view) : std::span<const uint32_t>(),
      shapes != nullptr ? shapes->num_shapes : 0);
  if (options.brute_force) {
    run.BruteForce(&local, start);
  } else if (indexed) {
    // The index's candidates per hand searched (the left hand's from the mirrored query), as
    // pairs of the run's slots: the left hand's rolls follow the right hand's in a both-hand run.
    IndexSearchOptions index_options = options.index;
    index_options.num_threads = threads;
    std::vector<uint32_t> pairs;
    size_t first_slot = 0;
    for (Hand h : {Hand::kRight, Hand::kLeft}) {
      if (options.hand != Hand::kEither && options.hand != h) continue;
      std::vector<Point2f> mirrored;
      if (h == Hand::kLeft) {
        mirrored.assign(query_px.begin(), query_px.end());
        for (Point2f& p : mirrored) p.x = -p.x;
      }
      const std::vector<Candidate> candidates = index_->Candidates(
          h == Hand::kLeft ? std::span<const Point2f>(mirrored) : query_px, index_options, pool);
      local.candidates += candidates.size();
      for (const Candidate& c : candidates) {
        if (c.view >= db_->num_views() || c.roll >= db_->num_rolls()) continue;
        pairs.push_back(static_cast<uint32_t>((first_slot + c.roll) * db_->num_views() + c.view));
      }
      first_slot += db_->num_rolls();
    }
    local.seconds_index = SecondsSince(start);
    const auto bounds_start = std::chrono::steady_clock::now();
    run.BoundCandidates(std::move(pairs));
    local.seconds_bounds = SecondsSince(bounds_start);
    const auto refine_start = std::chrono::steady_clock::now();
    run.Refine();
    local.seconds_refine = SecondsSince(refine_start);
  } else {
    run.Bounds();
    local.seconds_bounds = SecondsSince(start);
    const auto refine_start = std::chrono::steady_clock::now();
    run.Refine();
    local.seconds_refine = SecondsSince(refine_start);
  }
  run.AddInto(&local);
  std::vector<Match> matches = run.Matches();
  local.seconds_total = SecondsSince(start);
  if (stats != nullptr) *stats = local;
  return matches;
}

}  // namespace handdb
