#include "query/searcher.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <optional>

#include "base/progress.h"
#include "base/thread_pool.h"
#include "query/chamfer.h"
#include "query/coarse_bound.h"
#include "query/distance_transform.h"

namespace handdb {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Relative slack on abandonment thresholds so float rounding can never drop a pair that ties
// the k-th best (abandoning is only ever allowed for pairs strictly worse than it).
constexpr double kAbandonSlack = 1e-12;

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

struct Scored {
  double distance = 0;
  double a = 0;
  double b = 0;
  double lower_bound = 0;
  view_id_t view = 0;
  roll_id_t roll = 0;
};

// The total order of results: distance, then view id, then roll.
bool Before(const Scored& x, const Scored& y) {
  if (x.distance != y.distance) return x.distance < y.distance;
  if (x.view != y.view) return x.view < y.view;
  return x.roll < y.roll;
}

// Shared top-k under a mutex; threshold() is the k-th best distance (+inf until k are known),
// readable without the lock.
class TopK {
 public:
  // `bound`: pairs above it are never wanted (the other hand's k-th best, or +inf).
  TopK(size_t k, double bound) : k_(k), threshold_(bound) { items_.reserve(k + 1); }

  void Insert(const Scored& s) {
    if (s.distance > threshold_.load(std::memory_order_relaxed)) return;
    std::lock_guard<std::mutex> lock(mu_);
    if (items_.size() == k_ && !Before(s, items_.back())) return;
    // A pair is scored once (ScoreRollBest marks what it scored); kept as a guard.
    for (const Scored& it : items_) {
      if (it.view == s.view && it.roll == s.roll) return;
    }
    items_.insert(std::upper_bound(items_.begin(), items_.end(), s, Before), s);
    if (items_.size() > k_) items_.pop_back();
    if (items_.size() == k_) {
      threshold_.store(std::min(threshold_.load(std::memory_order_relaxed), items_.back().distance),
                       std::memory_order_relaxed);
    }
  }
  double threshold() const { return threshold_.load(std::memory_order_relaxed); }
  std::vector<Scored> items() const { return items_; }

 private:
  size_t k_;
  std::mutex mu_;
  std::vector<Scored> items_;
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

// Per-query state shared by the workers.
class QueryContext {
 public:
  QueryContext(const Database& db,
               std::span<const int32_t> max_abs,
               const CoarseFields* coarse,
               std::span<const Point2f> query,
               const SearchOptions& options)
      : db_(db),
        options_(options),
        query_(query),
        max_abs_(max_abs),
        coarse_(coarse),
        rolled_(db.num_rolls()),
        histograms_(coarse != nullptr ? db.num_rolls() : 0),
        point_cells_(coarse != nullptr ? db.num_rolls() : 0),
        scan_d2_(ResolveNumThreads(options.num_threads)),
        rolled_max_abs_(db.num_rolls()),
        query_trees_(db.num_rolls()),
        query_tree_once_(db.num_rolls()),
        caches_(ResolveNumThreads(options.num_threads)) {}

  // The query rotated by -angle(r) and quantised.
  void PrepareRoll(roll_id_t r) {
    rolled_[r] = RotateAndQuantise(query_, -RollAngle(r, db_.num_rolls()));
    int32_t m = 0;
    for (const PointQ& p : rolled_[r]) {
      m = std::max({m, std::abs(static_cast<int32_t>(p.x)), std::abs(static_cast<int32_t>(p.y))});
    }
    rolled_max_abs_[r] = m;
    if (coarse_ != nullptr) {
      histograms_[r].Build(rolled_[r]);
      point_cells_[r].resize(rolled_[r].size());
      for (size_t i = 0; i < rolled_[r].size(); ++i) {
        point_cells_[r][i] = static_cast<int16_t>(CoarseGrid::CellOf(rolled_[r][i]));
      }
    }
  }

  // L_A(v, r) of query/coarse_field.h (px), 0 without coarse fields.
  double CoarseBound(view_id_t v, roll_id_t r) const {
    if (coarse_ == nullptr) return 0.0;
    return histograms_[r].LowerBound(coarse_->field(v), rolled_[r].size());
  }
  // A lower bound of B(v, r) from a stored bound L <= L_A + L_B: L - L_A <= L_B (the same L_A
  // computation, so the subtraction is exact up to the last rounding, which goes down).
  double BLowerBound(view_id_t v, roll_id_t r, double stored_px) const {
    if (coarse_ == nullptr) return stored_px;
    return std::max(0.0, (stored_px - CoarseBound(v, r)) * (1 - 1e-12));
  }
  // The kd-tree over the rolled query, built on first use: rolls whose pairs are all pruned
  // never get one (and the trees do not exist during the bounds step).
  const KdTree& QueryTree(roll_id_t r) {
    std::call_once(query_tree_once_[r], [&] {
      query_trees_[r] = std::make_unique<KdTree>(rolled_[r], options_.kdtree);
    });
    return *query_trees_[r];
  }
  std::span<const PointQ> rolled(roll_id_t r) const { return rolled_[r]; }
  // max_i |rolled(r2)[i] + rolled(r)[i]| (px): how far rolled(r2) is from rolled(r) turned by
  // 180 degrees, point by point (both are the query's points in the same order). For r2 = r + R/2
  // it is 0 unless a coordinate sits on a rounding tie; either way d(y, rolled(r2)) >=
  // d(-y, rolled(r)) - gap for every y, so roll r's grid read at -y, minus the gap, bounds B of
  // roll r2.
  double NegationGap(roll_id_t r, roll_id_t r2) const {
    const std::vector<PointQ>& a = rolled_[r];
    const std::vector<PointQ>& b = rolled_[r2];
    THROW_CHECK_EQ(a.size(), b.size());
    int64_t worst = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      const int64_t dx = static_cast<int64_t>(a[i].x) + b[i].x;
      const int64_t dy = static_cast<int64_t>(a[i].y) + b[i].y;
      worst = std::max(worst, dx * dx + dy * dy);
    }
    // Rounded up: a slightly larger gap keeps the bound valid.
    return worst == 0 ? 0.0 : std::sqrt(static_cast<double>(worst)) / kPointScale * (1 + 1e-12);
  }

  // The kd-tree over view v's points from worker `worker`'s cache. Pairs are visited in
  // increasing bound and the rolls of one view have similar bounds, so a small per-worker LRU
  // cache catches the reuse while memory stays bounded (a tree over 600 points is ~10 KB;
  // caching every refined view cost ~1x the database size on the paper-size benchmark). On the
  // real paper database 8 entries per worker built 6,436 trees for 6,556 refined pairs and 2
  // entries the same within 1%, so 2 it is.
  const KdTree& ViewTree(view_id_t v, int worker) {
    auto& cache = caches_[worker];
    for (size_t i = 0; i < cache.size(); ++i) {
      if (cache[i].first == v) {
        std::rotate(cache.begin(), cache.begin() + i, cache.begin() + i + 1);
        return *cache.front().second;
      }
    }
    if (cache.size() == kTreeCacheSize) cache.pop_back();
    cache.emplace(cache.begin(), v, std::make_unique<KdTree>(db_.points(v), options_.kdtree));
    num_view_trees_.fetch_add(1, std::memory_order_relaxed);
    return *cache.front().second;
  }

  // Exact D_c of (v, r); returns false (abandoned) once it provably exceeds `threshold`.
  // `lower_bound` <= B(v, r) (0 if unknown): A goes first, abandoned as soon as
  // lower_bound + partial A exceeds the threshold, then B, abandoned once A + partial B does.
  bool Score(
      view_id_t v, roll_id_t r, double threshold, double lower_bound, int worker, Scored* out) {
    const std::span<const PointQ> view = db_.points(v);
    const std::span<const PointQ> q = rolled_[r];
    const double nv = static_cast<double>(view.size());
    const double nq = static_cast<double>(q.size());
    bool stopped = false;
    const double limit_a = Limit(threshold, lower_bound, nq);
    if (limit_a < 0) return false;
    double sum_a = 0;
    // Brute force keeps the kd-trees: it is the reference the scans are tested against.
    if (!options_.brute_force && max_abs_[v] <= kSmallCoordLimit &&
        rolled_max_abs_[r] <= kSmallCoordLimit) {
      if (!ScanA(v, r, limit_a, worker, &sum_a)) {
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
    const double sum_b = QueryTree(r).SumNearestDistances(view, limit_b, &stopped);
    if (stopped) return false;
    out->a = a;
    out->b = sum_b / nv;
    out->distance = out->a + out->b;
    out->view = v;
    out->roll = r;
    return true;
  }

  // The sum of A for (v, r) by linear scans of the view's points (no kd-tree: for a few hundred
  // points a vectorised scan per query point is cheaper than building a tree that one pair
  // uses), abandoned as soon as a lower bound of the whole sum exceeds `limit`: the exact
  // distances of the points scanned so far plus the coarse bound F_v(cell) of the others
  // (query/coarse_field.h; 0 without coarse fields). Points are scanned spread out first (every
  // step-th point, then the gaps), so the bound rises quickly. A pair that is not abandoned gets
  // the same sum as the kd-tree path, bit for bit: the nearest squared distances are exact
  // integers either way, and they are summed in the query's order.
  bool ScanA(view_id_t v, roll_id_t r, double limit, int worker, double* sum_out) {
    const std::span<const PointQ> view = db_.points(v);
    const std::span<const PointQ> q = rolled_[r];
    std::vector<int32_t>& d2 = scan_d2_[worker];
    d2.resize(q.size());
    const double stop = limit == kInf ? kInf : limit * (1 + 1e-9) + 1e-9;
    const uint8_t* field = coarse_ != nullptr ? coarse_->field(v) : nullptr;
    const int16_t* cells = coarse_ != nullptr ? point_cells_[r].data() : nullptr;
    double bound = coarse_ != nullptr ? CoarseBound(v, r) * static_cast<double>(q.size()) : 0.0;
    const size_t step = std::max<size_t>(1, q.size() / kScanSpread);
    for (size_t offset = 0; offset < step; ++offset) {
      for (size_t i = offset; i < q.size(); i += step) {
        d2[i] = NearestSquaredSmall(q[i], view);
        double gain = std::sqrt(static_cast<double>(d2[i])) / static_cast<double>(kPointScale);
        if (field != nullptr && cells[i] >= 0) {
          gain -= static_cast<double>(field[cells[i]]) / CoarseGrid::kValueUnitsPerPx;
        }
        bound += gain;
        if (bound > stop) return false;
      }
    }
    double sum = 0;
    for (size_t i = 0; i < q.size(); ++i) {
      sum += std::sqrt(static_cast<double>(d2[i])) / static_cast<double>(kPointScale);
    }
    if (sum > limit) return false;
    *sum_out = sum;
    return true;
  }

  uint64_t num_view_trees() const { return num_view_trees_.load(); }
  uint64_t num_probe_abandoned() const { return probe_abandoned_.load(); }

 private:
  const Database& db_;
  const SearchOptions& options_;
  std::span<const Point2f> query_;
  std::span<const int32_t> max_abs_;  // per view: max |x|, |y| (PointQ units)
  const CoarseFields* coarse_;        // nullptr: no A bound
  std::vector<std::vector<PointQ>> rolled_;
  std::vector<CellHistogram> histograms_;          // per roll, with coarse fields
  std::vector<std::vector<int16_t>> point_cells_;  // per roll: each point's coarse cell or -1
  static constexpr size_t kScanSpread = 64;        // points in ScanA's first spread-out pass
  std::vector<std::vector<int32_t>> scan_d2_;      // per worker: ScanA's squared distances
  std::vector<int32_t> rolled_max_abs_;
  std::atomic<uint64_t> probe_abandoned_{0};
  std::vector<std::unique_ptr<KdTree>> query_trees_;
  std::vector<std::once_flag> query_tree_once_;
  static constexpr size_t kTreeCacheSize = 2;
  std::vector<std::vector<std::pair<view_id_t, std::unique_ptr<KdTree>>>> caches_;
  std::atomic<uint64_t> num_view_trees_{0};
};

}  // namespace

bool SearchOptions::Check() const {
  CHECK_OPTION_GT(top_k, 0);
  CHECK_OPTION(num_threads == -1 || num_threads >= 1);
  CHECK_OPTION((DistanceGridOptions{dt_cell_px, 170.0f}.Check()));
  return true;
}

Searcher::Searcher(std::shared_ptr<const Database> db) : db_(std::move(db)) {
  THROW_CHECK(db_ != nullptr);
  max_abs_.resize(db_->num_views());
  for (view_id_t v = 0; v < db_->num_views(); ++v) {
    int32_t m = 0;
    for (const PointQ& p : db_->points(v)) {
      m = std::max({m, std::abs(static_cast<int32_t>(p.x)), std::abs(static_cast<int32_t>(p.y))});
    }
    max_abs_[v] = m;
  }
  // The grid holds distances to the rolled query, looked up only at view points; its bounds
  // are the same at every node whatever the extent (it grows to contain the query), so the
  // smallest extent that keeps every view on the grid gives identical bounds at the least cost.
  // Views are normalised to lie within 166.3 px of the origin, in practice ~115 px: half the
  // nodes of the 170 px default (docs/query.md).
  const int32_t db_max_abs =
      max_abs_.empty() ? 0 : *std::max_element(max_abs_.begin(), max_abs_.end());
  grid_half_extent_px_ =
      std::clamp(static_cast<float>(db_max_abs) / kPointScale + 1.0f, 8.0f, 2000.0f);
  coarse_ = CoarseFields(*db_, -1);
}

Searcher::~Searcher() = default;

Result<std::unique_ptr<Searcher>> Searcher::Open(const std::filesystem::path& dir) {
  Result<Database> db = Database::Open(dir);
  if (!db.ok()) return db.status();
  return std::make_unique<Searcher>(std::make_shared<const Database>(std::move(db).value()));
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

// One query's stages, sharing the query context, the top k and the counters: BruteForce(), or
// Bounds() then Refine(); then Matches().
class QueryRun {
 public:
  QueryRun(const Database& db,
           std::span<const int32_t> max_abs,
           float grid_half_extent_px,
           const CoarseFields* coarse,
           std::span<const Point2f> query_px,
           const SearchOptions& options,
           double threshold,
           int threads,
           ThreadPool* pool,
           Hand hand,
           std::chrono::steady_clock::time_point progress_since)
      : db_(db),
        max_abs_(max_abs),
        grid_half_extent_px_(grid_half_extent_px),
        options_(options),
        threads_(threads),
        pool_(pool),
        num_views_(db.num_views()),
        num_rolls_(db.num_rolls()),
        k_(static_cast<size_t>(options.top_k)),
        ctx_(db, max_abs, coarse, query_px, options),
        top_(k_, threshold),
        hand_(hand),
        progress_since_(progress_since) {}

  // The reference: exact D_c for every (view, roll).
  void BruteForce(SearchStats* stats, std::chrono::steady_clock::time_point start) {
    ParallelFor(
        num_rolls_,
        threads_,
        [&](size_t r, int) {
          ctx_.PrepareRoll(static_cast<roll_id_t>(r));
          return true;
        },
        pool_);
    stats->seconds_bounds = Seconds(start);
    const auto refine_start = std::chrono::steady_clock::now();
    const auto progress = MakeProgress("brute force", num_views_ * num_rolls_, "pairs");
    ParallelFor(
        num_views_,
        threads_,
        [&](size_t v, int worker) {
          if (!db_.points(static_cast<view_id_t>(v)).empty()) {
            for (roll_id_t r = 0; r < num_rolls_; ++r) {
              Scored s;
              ctx_.Score(static_cast<view_id_t>(v), r, kInf, 0.0, worker, &s);
              top_.Insert(s);
            }
            refined_.fetch_add(num_rolls_, std::memory_order_relaxed);
          }
          progress->Add(num_rolls_);
          return true;
        },
        pool_);
    stats->seconds_refine = Seconds(refine_start);
  }

  // Step 1: lower bounds, roll-major (one distance transform per roll, reused for every view),
  // index r * num_views + v. The threshold is learnt on the way: after each roll its best few
  // pairs are scored exactly, and a pair's bound stops accumulating as soon as it exceeds the
  // current k-th best D_c (the partial sum is still a valid lower bound, and already too large to
  // matter).
  //
  // With an even number of rolls, roll r + R/2 is roll r turned by 180 degrees: d(y, -Q) =
  // d(-y, Q), so one grid serves both, read at -y for the second (minus the point-by-point gap
  // between the two rolled queries, 0 but for rounding ties): half the distance transforms.
  std::vector<Bound> Bounds() {
    std::vector<Bound> bound(num_views_ * num_rolls_);
    const DistanceGridOptions grid_options{options_.dt_cell_px, grid_half_extent_px_};
    std::vector<DistanceGrid> grids(threads_, DistanceGrid(grid_options));
    const bool pairs = num_rolls_ >= 2 && num_rolls_ % 2 == 0;
    const uint32_t tasks = pairs ? num_rolls_ / 2 : num_rolls_;
    const auto progress = MakeProgress("bounds", num_rolls_, "rolls");
    ParallelFor(
        tasks,
        threads_,
        [&](size_t ri, int worker) {
          const roll_id_t r = static_cast<roll_id_t>(ri);
          ctx_.PrepareRoll(r);
          DistanceGrid& grid = grids[worker];
          grid.Build(ctx_.rolled(r));
          Bound* out = bound.data() + ri * num_views_;
          BoundRoll(grid, r, /*negate=*/false, /*gap_px=*/0.0, out);
          ScoreRollBest(r, out, worker);
          if (pairs) {
            const roll_id_t r2 = static_cast<roll_id_t>(r + num_rolls_ / 2);
            ctx_.PrepareRoll(r2);
            Bound* out2 = bound.data() + static_cast<size_t>(r2) * num_views_;
            BoundRoll(grid, r2, /*negate=*/true, ctx_.NegationGap(r, r2), out2);
            ScoreRollBest(r2, out2, worker);
          }
          progress->Add(pairs ? 2 : 1);
          return true;
        },
        pool_);
    return bound;
  }

  // Step 2: visit pairs in increasing bound. First the k smallest bounds give a threshold,
  // then only pairs whose bound is <= it are sorted and visited.
  void Refine(const std::vector<Bound>& bound) {
    const size_t n = bound.size();
    auto by_bound = [&](uint32_t x, uint32_t y) {
      return bound[x] != bound[y] ? bound[x] < bound[y] : x < y;
    };
    // The k smallest bounds with a bounded max-heap (no N-sized index array).
    std::vector<uint32_t> first;
    first.reserve(k_ + 1);
    for (uint32_t i = 0; i < n; ++i) {
      if (bound[i] == kNoBound) continue;
      if (first.size() < k_) {
        first.push_back(i);
        std::push_heap(first.begin(), first.end(), by_bound);
      } else if (by_bound(i, first.front())) {
        std::pop_heap(first.begin(), first.end(), by_bound);
        first.back() = i;
        std::push_heap(first.begin(), first.end(), by_bound);
      }
    }
    std::sort(first.begin(), first.end(), by_bound);
    Visit(bound, first);
    const double t0 = top_.threshold();
    std::vector<uint32_t> rest;
    const uint32_t last_first = first.empty() ? 0 : first.back();
    for (uint32_t i = 0; i < n; ++i) {
      if (bound[i] != kNoBound && BoundPx(bound[i]) <= t0 &&
          (first.empty() || by_bound(last_first, i))) {
        rest.push_back(i);
      }
    }
    std::sort(rest.begin(), rest.end(), by_bound);
    // `rest` bounds the pairs to refine; the visit stops early once bounds pass the k-th best.
    const auto progress = MakeProgress("refine", rest.size(), "pairs");
    Visit(bound, rest, progress.get());
    progress->SetTotal(progress->done());
  }

  // The top k, best first, with labels rolled (and mirrored back for kLeft) and shape names.
  std::vector<Match> Matches(Hand hand) const {
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
      if (hand == Hand::kLeft) m.label = MirrorLabel(m.label);
      m.hand = hand;
      m.shape_name = std::string(db_.shape_name(m.label.shape_id));
      matches.push_back(std::move(m));
    }
    return matches;
  }

  void AddInto(SearchStats* stats) const {
    stats->refined += refined_.load();
    stats->abandoned += abandoned_.load();
    stats->view_trees += ctx_.num_view_trees();
    stats->probe_abandoned += ctx_.num_probe_abandoned();
  }

 private:
  // The bound of every view against one roll's distance grid, into out[v]. negate: the grid is
  // of a roll whose query is rolled(r) turned by 180 degrees, up to gap_px per point (Bounds()).
  void BoundRoll(
      const DistanceGrid& grid, roll_id_t r, bool negate, double gap_px, Bound* out) const {
    constexpr size_t kChunk = 64;
    for (view_id_t v = 0; v < num_views_; ++v) {
      const std::span<const PointQ> pts = db_.points(v);
      if (pts.empty()) {
        out[v] = kNoBound;
        continue;
      }
      // The coarse A bound first: a short dot product that on real photos prunes most pairs
      // alone; then the B bound, stopped as soon as the sum is above the k-th best.
      const double threshold = top_.threshold();
      const double bound_a = ctx_.CoarseBound(v, r);
      if (bound_a > threshold) {
        out[v] = BoundBelow(bound_a);
        continue;
      }
      const double n = static_cast<double>(pts.size());
      const double limit = Limit(threshold, bound_a, n) + gap_px * n;
      const bool fast = grid.Covers(max_abs_[v]);
      double sum = 0;
      for (size_t i = 0; i < pts.size() && sum <= limit; i += kChunk) {
        const auto chunk = pts.subspan(i, std::min(kChunk, pts.size() - i));
        sum += fast ? grid.SumLowerBoundsFast(chunk, negate) : grid.SumLowerBounds(chunk, negate);
      }
      const double mean = sum / n;
      out[v] = BoundBelow(bound_a + mean - DistanceGrid::MeanLowerBoundMargin(pts.size(), mean) -
                          gap_px);
    }
  }

  // Scores this roll's most promising pairs now so later rolls can stop early.
  // A pair scored here is marked kNoBound so that Refine does not score it again (its D_c is
  // in the top k already, or was above the threshold, which only falls).
  void ScoreRollBest(roll_id_t r, Bound* out, int worker) {
    const size_t m = std::min<size_t>(num_views_, top_.threshold() == kInf ? k_ : 2);
    std::vector<uint32_t> best;
    best.reserve(m + 1);
    auto less = [&](uint32_t x, uint32_t y) { return out[x] != out[y] ? out[x] < out[y] : x < y; };
    for (uint32_t v = 0; v < num_views_; ++v) {
      if (out[v] == kNoBound) continue;
      if (best.size() < m) {
        best.push_back(v);
        std::push_heap(best.begin(), best.end(), less);
      } else if (m > 0 && less(v, best.front())) {
        std::pop_heap(best.begin(), best.end(), less);
        best.back() = v;
        std::push_heap(best.begin(), best.end(), less);
      }
    }
    for (uint32_t v : best) {
      const double threshold = top_.threshold();
      if (BoundPx(out[v]) > threshold) continue;
      refined_.fetch_add(1, std::memory_order_relaxed);
      Scored sc;
      if (ctx_.Score(v, r, threshold, ctx_.BLowerBound(v, r, BoundPx(out[v])), worker, &sc)) {
        sc.lower_bound = BoundPx(out[v]);
        top_.Insert(sc);
      } else {
        abandoned_.fetch_add(1, std::memory_order_relaxed);
      }
      out[v] = kNoBound;
    }
  }

  // Scores the pairs of `order` (increasing bound) until a bound exceeds the k-th best.
  void Visit(const std::vector<Bound>& bound,
             std::span<const uint32_t> order,
             Progress* progress = nullptr) {
    ParallelFor(
        order.size(),
        threads_,
        [&](size_t i, int worker) {
          const uint32_t idx = order[i];
          const double threshold = top_.threshold();
          if (BoundPx(bound[idx]) > threshold) return false;  // every later pair: a larger bound
          if (progress != nullptr) progress->Add();
          const view_id_t v = idx % num_views_;
          const roll_id_t r = static_cast<roll_id_t>(idx / num_views_);
          refined_.fetch_add(1, std::memory_order_relaxed);
          Scored s;
          if (ctx_.Score(
                  v, r, threshold, ctx_.BLowerBound(v, r, BoundPx(bound[idx])), worker, &s)) {
            s.lower_bound = BoundPx(bound[idx]);
            top_.Insert(s);
          } else {
            abandoned_.fetch_add(1, std::memory_order_relaxed);
          }
          return true;
        },
        pool_);
  }

  // One phase's progress line (SearchOptions::progress), e.g. "query refine (left)".
  std::unique_ptr<Progress> MakeProgress(const std::string& phase,
                                         uint64_t total,
                                         const char* unit) const {
    std::string label = "query " + phase;
    if (options_.hand == Hand::kEither) label += " (" + std::string(HandName(hand_)) + ")";
    auto progress = std::make_unique<Progress>(label, total, options_.progress, unit);
    progress->QuietUnlessSlow(progress_since_);
    return progress;
  }

  const Database& db_;
  std::span<const int32_t> max_abs_;
  float grid_half_extent_px_;
  const SearchOptions& options_;
  const int threads_;
  ThreadPool* const pool_;
  const size_t num_views_;
  const uint32_t num_rolls_;
  const size_t k_;
  QueryContext ctx_;
  TopK top_;
  std::atomic<uint64_t> refined_{0};
  std::atomic<uint64_t> abandoned_{0};
  const Hand hand_;
  const std::chrono::steady_clock::time_point progress_since_;
};

}  // namespace

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

std::vector<Match> Searcher::SearchOnce(std::span<const Point2f> query_px,
                                        const SearchOptions& options,
                                        double threshold,
                                        Hand hand,
                                        int threads,
                                        ThreadPool* pool,
                                        std::chrono::steady_clock::time_point progress_since,
                                        SearchStats* stats) const {
  const auto start = std::chrono::steady_clock::now();
  QueryRun run(*db_,
               max_abs_,
               grid_half_extent_px_,
               options.coarse_bound && !coarse_.empty() ? &coarse_ : nullptr,
               query_px,
               options,
               threshold,
               threads,
               pool,
               hand,
               progress_since);
  SearchStats local;
  if (options.brute_force) {
    run.BruteForce(&local, start);
  } else {
    const std::vector<Bound> bound = run.Bounds();
    local.bounded = bound.size();
    local.seconds_bounds = Seconds(start);
    const auto refine_start = std::chrono::steady_clock::now();
    run.Refine(bound);
    local.seconds_refine = Seconds(refine_start);
  }
  stats->bounded += local.bounded;
  stats->seconds_bounds += local.seconds_bounds;
  stats->seconds_refine += local.seconds_refine;
  stats->searches += 1;
  run.AddInto(stats);
  return run.Matches(hand);
}

Result<std::vector<Match>> Searcher::Search(std::span<const Point2f> query_px,
                                            const SearchOptions& options,
                                            SearchStats* stats) const {
  const auto start = std::chrono::steady_clock::now();
  if (Status s = CheckQuery(query_px, options); !s.ok()) return s;

  const int threads = ResolveNumThreads(options.num_threads);
  // One pool for the query's parallel loops (both hands); the calling thread is worker 0.
  std::optional<ThreadPool> pool_storage;
  ThreadPool* pool = threads > 1 ? &pool_storage.emplace(threads - 1) : nullptr;
  const auto progress_since = options.progress_since == std::chrono::steady_clock::time_point{}
                                  ? start
                                  : options.progress_since;
  SearchStats local;
  local.virtual_views = db_->num_virtual_views();
  local.query_points = query_px.size();

  std::vector<Match> matches;
  if (options.hand != Hand::kLeft) {
    matches =
        SearchOnce(query_px, options, kInf, Hand::kRight, threads, pool, progress_since, &local);
  }
  if (options.hand != Hand::kRight) {
    // x -> -x is exact in float, so the mirrored query of a mirrored view is the view itself.
    std::vector<Point2f> mirrored(query_px.begin(), query_px.end());
    for (Point2f& p : mirrored) p.x = -p.x;
    // Only pairs that can enter the merged top-k matter: those at or below the right hand's
    // k-th best. Brute force stays the plain reference and searches both in full.
    const size_t k = static_cast<size_t>(options.top_k);
    const double threshold =
        !options.brute_force && matches.size() == k ? matches.back().distance : kInf;
    std::vector<Match> left = SearchOnce(
        mirrored, options, threshold, Hand::kLeft, threads, pool, progress_since, &local);
    for (Match& m : left) matches.push_back(std::move(m));
    std::stable_sort(matches.begin(), matches.end(), [](const Match& x, const Match& y) {
      if (x.distance != y.distance) return x.distance < y.distance;
      if (x.view_id != y.view_id) return x.view_id < y.view_id;
      if (x.roll != y.roll) return x.roll < y.roll;
      return x.hand == Hand::kRight && y.hand == Hand::kLeft;
    });
    if (matches.size() > k) matches.resize(k);
  }
  local.seconds_total = Seconds(start);
  if (stats != nullptr) *stats = local;
  return matches;
}

}  // namespace handdb
