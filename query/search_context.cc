#include "query/search_context.h"

#include <algorithm>
#include <bit>
#include <utility>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "query/chamfer.h"

namespace handdb::search_internal {

SearchContext::SearchContext(const Database& db,
                             std::span<const int32_t> max_abs,
                             std::span<const uint8_t> y_sorted,
                             const CoarseFields* coarse,
                             std::span<const Point2f> query,
                             std::vector<Slot> slots,
                             const SearchOptions& options,
                             int num_workers)
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
      neighbour_caches_(static_cast<size_t>(num_workers)),
      scan_orders_(static_cast<size_t>(num_workers)),
      scan_d2_(static_cast<size_t>(num_workers)),
      scan_prior_(static_cast<size_t>(num_workers)),
      rolled_max_abs_(slots_.size()),
      query_trees_(slots_.size()),
      query_tree_once_(slots_.size()),
      query_buckets_(slots_.size()),
      query_buckets_once_(slots_.size()),
      caches_(static_cast<size_t>(num_workers)),
      bucket_caches_(static_cast<size_t>(num_workers)),
      row_caches_(static_cast<size_t>(num_workers)) {
  for (const Slot& s : slots_) {
    if (s.hand == Hand::kLeft && mirrored_.empty()) {
      // x -> -x is exact in float, so the mirrored query of a mirrored view is the view itself.
      mirrored_.assign(query.begin(), query.end());
      for (Point2f& p : mirrored_) p.x = -p.x;
    }
  }
}

void SearchContext::PrepareSlot(size_t s) {
  const std::span<const Point2f> source =
      slots_[s].hand == Hand::kLeft ? std::span<const Point2f>(mirrored_) : query_;
  rolled_[s] = RotateAndQuantise(source, -RollAngle(slots_[s].roll, db_.num_rolls()));
  int32_t m = 0;
  for (const PointQ& p : rolled_[s]) {
    m = std::max({m, std::abs(static_cast<int32_t>(p.x)), std::abs(static_cast<int32_t>(p.y))});
  }
  rolled_max_abs_[s] = m;
  if (coarse_ != nullptr) PrepareSlotCells(s);
}

void SearchContext::PrepareSlotCells(size_t s) {
  const std::vector<PointQ>& pts = rolled_[s];
  histograms_[s].Build(pts, coarse_->kind());
  point_cells_[s].resize(pts.size());
  // What the scans' per-point bounds read: the distinct cells and each point's gaps to the
  // neighbouring cells and its own (FieldGaps).
  // The distinct cells in increasing order, from a bitmap of the grid's cells (no sort).
  constexpr size_t kWords = (CoarseGrid::kCells + 63) / 64;
  uint64_t seen[kWords] = {};
  for (size_t i = 0; i < pts.size(); ++i) {
    const int c = CoarseGrid::CellOf(pts[i]);
    point_cells_[s][i] = static_cast<int16_t>(c);
    if (c >= 0) seen[c >> 6] |= uint64_t{1} << (c & 63);
  }
  std::vector<uint16_t>& distinct = distinct_cells_[s];
  distinct.clear();
  for (size_t w = 0; w < kWords; ++w) {
    for (uint64_t bits = seen[w]; bits != 0; bits &= bits - 1) {
      distinct.push_back(
          static_cast<uint16_t>(64 * w + static_cast<size_t>(std::countr_zero(bits))));
    }
  }
  point_gaps_[s].resize(8 * pts.size());
  point_own_gaps_[s].resize(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    uint8_t g[9];
    FieldGaps(coarse_->kind(), pts[i], g);
    std::copy(g, g + 8, &point_gaps_[s][8 * i]);
    point_own_gaps_[s][i] = g[8];
  }
}

const KdTree& SearchContext::QueryTree(size_t s) {
  std::call_once(query_tree_once_[s],
                 [&] { query_trees_[s] = std::make_unique<KdTree>(rolled_[s], options_.kdtree); });
  return *query_trees_[s];
}

const PointBuckets& SearchContext::QueryBuckets(size_t s) {
  std::call_once(query_buckets_once_[s], [&] { query_buckets_[s].Build(rolled_[s]); });
  return query_buckets_[s];
}

const PointBuckets& SearchContext::ViewBuckets(view_id_t v, int worker) {
  return bucket_caches_[worker].Get(
      v, [&](PointBuckets& buckets) { buckets.Build(db_.SearchPoints(v)); });
}

double SearchContext::MemberGap(size_t base, const GridMember& m) const {
  const int64_t sx = m.flip == GridFlip::kX || m.flip == GridFlip::kXY ? -1 : 1;
  const int64_t sy = m.flip == GridFlip::kY || m.flip == GridFlip::kXY ? -1 : 1;
  return MappedGap(base, m.slot, [sx, sy, turned = m.turned](PointQ p) {
    const int64_t x = turned ? p.y : p.x;
    const int64_t y = turned ? -static_cast<int64_t>(p.x) : p.y;
    return std::pair<int64_t, int64_t>{sx * x, sy * y};
  });
}

template <typename Map>
double SearchContext::MappedGap(size_t base, size_t member, Map map) const {
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

const KdTree& SearchContext::ViewTree(view_id_t v, int worker) {
  return *caches_[worker].Get(v, [&](std::unique_ptr<KdTree>& tree) {
    tree = std::make_unique<KdTree>(db_.SearchPoints(v), options_.kdtree);
    num_view_trees_.fetch_add(1, std::memory_order_relaxed);
  });
}

bool SearchContext::Score(
    view_id_t v, size_t s, double threshold, double bound_b_px, int worker, Scored* out) {
  const std::span<const PointQ> view = db_.SearchPoints(v);
  const double nv = static_cast<double>(view.size());
  const double nq = static_cast<double>(rolled_[s].size());
  const double limit_a = Limit(threshold, bound_b_px, nq);
  if (limit_a < 0) return false;
  double sum_a = 0;
  if (!SumA(v, s, limit_a, worker, &sum_a)) return false;
  const double a = sum_a / nq;
  const double limit_b = Limit(threshold, a, nv);
  if (limit_b < 0) return false;
  double sum_b = 0;
  if (!SumB(view, s, limit_b, &sum_b)) return false;
  out->a = a;
  out->b = sum_b / nv;
  out->distance = out->a + out->b;
  out->view = v;
  out->roll = slots_[s].roll;
  out->hand = slots_[s].hand;
  return true;
}

bool SearchContext::SumA(view_id_t v, size_t s, double limit, int worker, double* sum) {
  // Brute force keeps the kd-trees: it is the reference the scans are tested against.
  if (!options_.brute_force && max_abs_[v] <= kSmallCoordLimit &&
      rolled_max_abs_[s] <= kSmallCoordLimit) {
    if (ScanA(v, s, limit, worker, sum)) return true;
    probe_abandoned_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  bool stopped = false;
  *sum = ViewTree(v, worker).SumNearestDistances(rolled_[s], limit, &stopped);
  return !stopped;
}

bool SearchContext::SumB(std::span<const PointQ> view, size_t s, double limit, double* sum) {
  bool stopped = false;
  const PointBuckets* buckets = options_.brute_force ? nullptr : &QueryBuckets(s);
  *sum = buckets != nullptr && buckets->usable()
             ? buckets->SumNearestDistances(view, limit, &stopped)
             : QueryTree(s).SumNearestDistances(view, limit, &stopped);
  return !stopped;
}

bool SearchContext::ScanA(view_id_t v, size_t s, double limit, int worker, double* sum_out) {
  const std::span<const PointQ> q = rolled_[s];
  std::vector<int32_t>& d2 = scan_d2_[worker];
  d2.resize(q.size());
  const double stop = limit == kInf ? kInf : limit * (1 + 1e-9) + 1e-9;
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
  if (!ScanNearest(v, s, worker, prior, stop, bound, d2)) return false;
  double sum = 0;
  for (size_t i = 0; i < q.size(); ++i) {
    sum += std::sqrt(static_cast<double>(d2[i])) / static_cast<double>(kPointScale);
  }
  if (sum > limit) return false;
  *sum_out = sum;
  return true;
}

bool SearchContext::ScanNearest(view_id_t v,
                                size_t s,
                                int worker,
                                std::span<const uint8_t> prior,
                                double stop,
                                double bound,
                                std::span<int32_t> d2) {
  const std::span<const PointQ> view = db_.SearchPoints(v);
  const std::span<const PointQ> q = rolled_[s];
  const int16_t* cells = coarse_ != nullptr ? point_cells_[s].data() : nullptr;
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
  return true;
}

uint64_t SearchContext::PointBounds(view_id_t v, size_t s, int worker, uint8_t* out) {
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

}  // namespace handdb::search_internal
