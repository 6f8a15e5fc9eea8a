#include "query/distance_transform.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <limits>

#include "base/status.h"
#include "query/simd.h"

namespace handdb {

bool DistanceGridOptions::Check() const {
  bool power_of_two_fraction = false;
  for (int k = 0; k <= 4; ++k) {
    if (cell_px == 1.0f / static_cast<float>(1 << k)) power_of_two_fraction = true;
  }
  CHECK_OPTION(power_of_two_fraction);
  CHECK_OPTION_GT(min_half_extent_px, 0.0f);
  CHECK_OPTION_LE(min_half_extent_px, 2000.0f);
  return true;
}

DistanceGrid::DistanceGrid(const DistanceGridOptions& options) : options_(options) {
  THROW_CHECK(options.Check());
  cell_u_ = static_cast<int>(std::lround(options.cell_px * kPointScale));
  shift_ = 0;
  while ((1 << shift_) < cell_u_) ++shift_;
  THROW_CHECK_EQ(1 << shift_, cell_u_);
}

namespace {

constexpr uint16_t kNoSeed = 0xFFFF;  // column pass: no seed in this column
// Largest grid side: a query far from the hand coarsens the grid instead of growing it (a
// 2049 x 2049 grid is 8 MB); up to 4 px cells, which still covers +-4000 px.
constexpr int kMaxGridSide = 2049;
constexpr int kMaxCellUnits = 64;

// out[i] = min(65535, floor(sqrt(d2[i]) * scale)): exact, since sqrt is correctly rounded,
// `scale` is a power of two, and no integer d2 has a scaled root within rounding distance below
// an integer. The AVX2 path gives the same values (same IEEE operations), four at a time.
#ifdef HANDDB_HAVE_AVX2_PATH
__attribute__((target("avx2"))) size_t RowToUnitsAvx2(const int32_t* d2,
                                                      size_t n,
                                                      double scale,
                                                      uint16_t* out) {
  const __m256d vscale = _mm256_set1_pd(scale);
  const __m256d vmax = _mm256_set1_pd(65535.0);
  size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(d2 + i));
    const __m256d r = _mm256_sqrt_pd(_mm256_cvtepi32_pd(v));
    const __m256d u = _mm256_min_pd(_mm256_floor_pd(_mm256_mul_pd(r, vscale)), vmax);
    alignas(16) int32_t lanes[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(lanes), _mm256_cvttpd_epi32(u));
    for (int l = 0; l < 4; ++l) out[i + l] = static_cast<uint16_t>(lanes[l]);
  }
  return i;
}
#endif

// row[x] = min(row[x], from[x] + 1) with kNoSeed + 1 = kNoSeed: one step of the column pass. A
// saturating add is that rule (from[x] < kNoSeed gives from[x] + 1, kNoSeed stays), so the AVX2
// path gives the same values, sixteen at a time.
#ifdef HANDDB_HAVE_AVX2_PATH
__attribute__((target("avx2"))) size_t RelaxRowAvx2(uint16_t* row, const uint16_t* from, size_t n) {
  const __m256i one = _mm256_set1_epi16(1);
  size_t x = 0;
  for (; x + 16 <= n; x += 16) {
    const __m256i f = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(from + x));
    const __m256i r = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(row + x));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(row + x),
                        _mm256_min_epu16(r, _mm256_adds_epu16(f, one)));
  }
  return x;
}
#endif

void RelaxRow(uint16_t* row, const uint16_t* from, size_t n) {
  size_t x = 0;
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveAvx2()) x = RelaxRowAvx2(row, from, n);
#endif
  for (; x < n; ++x) {
    const uint32_t via = from[x] == kNoSeed ? kNoSeed : from[x] + 1u;
    row[x] = static_cast<uint16_t>(std::min<uint32_t>(row[x], via));
  }
}

void RowToUnits(const int32_t* d2, size_t n, double scale, uint16_t* out) {
  size_t i = 0;
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveAvx2()) i = RowToUnitsAvx2(d2, n, scale, out);
#endif
  for (; i < n; ++i) {
    const double units = std::floor(std::sqrt(static_cast<double>(d2[i])) * scale);
    out[i] = static_cast<uint16_t>(std::min(units, 65535.0));
  }
}

}  // namespace

void DistanceGrid::Build(std::span<const PointQ> points) {
  THROW_CHECK(!points.empty());
  int max_abs = static_cast<int>(std::ceil(options_.min_half_extent_px * kPointScale));
  for (const PointQ& q : points) {
    max_abs = std::max({max_abs, std::abs(static_cast<int>(q.x)), std::abs(static_cast<int>(q.y))});
  }
  cell_u_ = static_cast<int>(std::lround(options_.cell_px * kPointScale));
  for (;;) {
    half_extent_u_ = (max_abs + cell_u_ - 1) / cell_u_ * cell_u_;
    size_ = 2 * half_extent_u_ / cell_u_ + 1;
    if (size_ <= kMaxGridSide || cell_u_ >= kMaxCellUnits) break;
    cell_u_ *= 2;
  }
  shift_ = 0;
  while ((1 << shift_) < cell_u_) ++shift_;
  THROW_CHECK_EQ(1 << shift_, cell_u_);
  fast_limit_ = half_extent_u_;
  const size_t n = static_cast<size_t>(size_);

  // Seeds: the node nearest to each point (distance 0 in the column pass).
  dt_.assign(n * n + 1, kNoSeed);
  double r_max_sq = 0;
  const double cell = cell_u_;
  for (const PointQ& q : points) {
    const int ix = NodeIndex(q.x);
    const int iy = NodeIndex(q.y);
    dt_[static_cast<size_t>(iy) * n + ix] = 0;
    const double dx = q.x - (static_cast<double>(ix) * cell - half_extent_u_);
    const double dy = q.y - (static_cast<double>(iy) * cell - half_extent_u_);
    r_max_sq = std::max(r_max_sq, dx * dx + dy * dy);
  }
  r_max_px_ = static_cast<float>(std::sqrt(r_max_sq) / kPointScale);

  // Pass 1, per column: distance in nodes to the nearest seed in the same column (two sweeps,
  // done row by row so memory is read contiguously).
  uint16_t* g = dt_.data();
  for (size_t y = 1; y < n; ++y) RelaxRow(g + y * n, g + (y - 1) * n, n);
  for (size_t y = n - 1; y-- > 0;) RelaxRow(g + y * n, g + (y + 1) * n, n);

  // Pass 2, per row: lower envelope of the parabolas (x - v)^2 + g(v)^2 over the columns v that
  // have a seed (Felzenszwalb & Huttenlocher 2012), in exact integer arithmetic: the boundary
  // between parabolas is kept as a fraction zn/zd (zd > 0) and compared by cross-multiplying, so
  // there is no division. Then floor(distance in 1/64 px) for the whole row (RowToUnits).
  row_f_.resize(n);
  row_v_.resize(n);
  row_zn_.resize(n + 1);
  row_zd_.resize(n + 1);
  row_d2_.resize(n);
  const double units_per_node = kUnitsPerPx * static_cast<double>(cell_u_) / kPointScale;
  for (size_t y = 0; y < n; ++y) {
    uint16_t* row = g + y * n;
    int k = -1;
    for (int q = 0; q < size_; ++q) {
      if (row[q] == kNoSeed) continue;
      const int64_t fq = static_cast<int64_t>(row[q]) * row[q];
      row_f_[q] = static_cast<int32_t>(fq);
      // Intersection of parabola q with parabola v: s = num / den, den = 2 (q - v) > 0.
      int64_t num = 0;
      int64_t den = 1;
      // Pop parabolas while s <= z[k]; z[0] = -inf, so k = 0 always stays.
      while (k >= 0) {
        const int64_t v = row_v_[k];
        num = fq + static_cast<int64_t>(q) * q - row_f_[v] - v * v;
        den = 2 * (q - v);
        if (k == 0 || num * row_zd_[k] > row_zn_[k] * den) break;
        --k;
      }
      ++k;
      row_v_[k] = q;
      row_zn_[k] = num;  // unused for k = 0 (-inf)
      row_zd_[k] = den;
    }
    THROW_CHECK_GE(k, 0);  // every column below or above a seed has a finite distance
    int j = 0;
    for (int q = 0; q < size_; ++q) {
      while (j < k && row_zn_[j + 1] < static_cast<int64_t>(q) * row_zd_[j + 1]) ++j;
      const int32_t dx = q - row_v_[j];
      row_d2_[q] = dx * dx + row_f_[row_v_[j]];
    }
    RowToUnits(row_d2_.data(), n, units_per_node, row);
  }

  // r_max + |p - n| for every position of p inside its cell.
  offset_table_.resize(static_cast<size_t>(cell_u_) * cell_u_);
  for (int fy = 0; fy < cell_u_; ++fy) {
    for (int fx = 0; fx < cell_u_; ++fx) {
      const double ox = fx - cell_u_ / 2;
      const double oy = fy - cell_u_ / 2;
      offset_table_[static_cast<size_t>(fy) * cell_u_ + fx] =
          static_cast<float>(std::sqrt(ox * ox + oy * oy) / kPointScale) + r_max_px_;
    }
  }
}

namespace {

bool FlipsX(GridFlip flip) { return flip == GridFlip::kX || flip == GridFlip::kXY; }
bool FlipsY(GridFlip flip) { return flip == GridFlip::kY || flip == GridFlip::kXY; }

}  // namespace

float DistanceGrid::LowerBound(PointQ p, GridFlip flip, bool turned) const {
  // 32-bit coordinates: -(-32768) is representable.
  const int fx = FlipsX(flip) ? -static_cast<int>(p.x) : p.x;
  const int fy = FlipsY(flip) ? -static_cast<int>(p.y) : p.y;
  const int x = turned ? -fy : fx;
  const int y = turned ? fx : fy;
  const int ax = std::abs(x);
  const int ay = std::abs(y);
  if (ax > fast_limit_ || ay > fast_limit_) {
    // Off the grid: distance to the box holding every point of the set.
    const double dx = std::max(0, ax - half_extent_u_);
    const double dy = std::max(0, ay - half_extent_u_);
    return static_cast<float>(std::sqrt(dx * dx + dy * dy) / kPointScale);
  }
  const int mask = cell_u_ - 1;
  const int half = cell_u_ / 2;
  const float off = offset_table_[(((y + half) & mask) << shift_) | ((x + half) & mask)];
  const float d =
      static_cast<float>(dt_[static_cast<size_t>(NodeIndex(y)) * size_ + NodeIndex(x)]) *
      (1.0f / kUnitsPerPx);
  return std::max(0.0f, d - off);
}

double DistanceGrid::SumLowerBounds(std::span<const PointQ> points,
                                    GridFlip flip,
                                    bool turned) const {
  double sum = 0;
  for (const PointQ& p : points) sum += LowerBound(p, flip, turned);
  return sum;
}

namespace {

#ifdef HANDDB_HAVE_AVX2_PATH
template <bool kNegX, bool kNegY, bool kTurn>
__attribute__((target("avx2"), always_inline)) inline __m256 Step(const PointQ* p,
                                                                  __m256i vbias,
                                                                  __m256i vhalf,
                                                                  __m256i vmask,
                                                                  __m256i vsize,
                                                                  __m128i vshift,
                                                                  __m256 zero,
                                                                  const uint16_t* dt,
                                                                  const float* table) {
  const __m256i v = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
  __m256i x = _mm256_srai_epi32(_mm256_slli_epi32(v, 16), 16);
  __m256i y = _mm256_srai_epi32(v, 16);
  // The point reflected in an axis (32-bit lanes, exact).
  if constexpr (kNegX) x = _mm256_sub_epi32(_mm256_setzero_si256(), x);
  if constexpr (kNegY) y = _mm256_sub_epi32(_mm256_setzero_si256(), y);
  // Then turned back: T^-1(x, y) = (-y, x).
  if constexpr (kTurn) {
    const __m256i turned_x = _mm256_sub_epi32(_mm256_setzero_si256(), y);
    y = x;
    x = turned_x;
  }
  const __m256i ix = _mm256_sra_epi32(_mm256_add_epi32(x, vbias), vshift);
  const __m256i iy = _mm256_sra_epi32(_mm256_add_epi32(y, vbias), vshift);
  const __m256i idx = _mm256_add_epi32(_mm256_mullo_epi32(iy, vsize), ix);
  const __m256i tx = _mm256_and_si256(_mm256_add_epi32(x, vhalf), vmask);
  const __m256i ty = _mm256_and_si256(_mm256_add_epi32(y, vhalf), vmask);
  const __m256i tidx = _mm256_or_si256(_mm256_sll_epi32(ty, vshift), tx);
  // 32-bit loads at 2-byte steps (dt_ has one padding element), low halves are the uint16 DT.
  const __m256i raw = _mm256_i32gather_epi32(reinterpret_cast<const int*>(dt), idx, 2);
  const __m256 d =
      _mm256_mul_ps(_mm256_cvtepi32_ps(_mm256_and_si256(raw, _mm256_set1_epi32(0xFFFF))),
                    _mm256_set1_ps(1.0f / DistanceGrid::kUnitsPerPx));
  const __m256 off = _mm256_i32gather_ps(table, tidx, 4);
  return _mm256_max_ps(_mm256_sub_ps(d, off), zero);
}

// Eight points per step: unpack int16 x/y, compute node and offset-table indices, two gathers.
// Returns the sum over the first n - n % 8 points; *done receives that count.
template <bool kNegX, bool kNegY, bool kTurn>
__attribute__((target("avx2"))) double SumLowerBoundsAvx2(const PointQ* pts,
                                                          size_t n,
                                                          const uint16_t* dt,
                                                          const float* table,
                                                          int mask,
                                                          int half,
                                                          int bias,
                                                          int shift,
                                                          int size,
                                                          size_t* done) {
  static_assert(sizeof(PointQ) == 4 && offsetof(PointQ, x) == 0 && offsetof(PointQ, y) == 2);
  const __m256i vbias = _mm256_set1_epi32(bias);
  const __m256i vhalf = _mm256_set1_epi32(half);
  const __m256i vmask = _mm256_set1_epi32(mask);
  const __m256i vsize = _mm256_set1_epi32(size);
  const __m128i vshift = _mm_cvtsi32_si128(shift);
  const __m256 zero = _mm256_setzero_ps();
  __m256 acc0 = zero;
  __m256 acc1 = zero;
  size_t i = 0;
  for (; i + 16 <= n; i += 16) {
    acc0 = _mm256_add_ps(
        acc0,
        Step<kNegX, kNegY, kTurn>(pts + i, vbias, vhalf, vmask, vsize, vshift, zero, dt, table));
    acc1 = _mm256_add_ps(acc1,
                         Step<kNegX, kNegY, kTurn>(
                             pts + i + 8, vbias, vhalf, vmask, vsize, vshift, zero, dt, table));
  }
  for (; i + 8 <= n; i += 8)
    acc0 = _mm256_add_ps(
        acc0,
        Step<kNegX, kNegY, kTurn>(pts + i, vbias, vhalf, vmask, vsize, vshift, zero, dt, table));
  alignas(32) float lanes[16];
  _mm256_store_ps(lanes, acc0);
  _mm256_store_ps(lanes + 8, acc1);
  double sum = 0;
  for (float f : lanes) sum += f;
  *done = i;
  return sum;
}

#endif

}  // namespace

template <bool kNegX, bool kNegY, bool kTurn>
double DistanceGrid::SumLowerBoundsFastImpl(std::span<const PointQ> points) const {
  const uint16_t* dt = dt_.data();
  const float* table = offset_table_.data();
  const int mask = cell_u_ - 1;
  const int half = cell_u_ / 2;
  const int bias = half_extent_u_ + half;
  const int shift = shift_;
  const int size = size_;
  float acc[4] = {0, 0, 0, 0};
  const size_t n = points.size();
  const PointQ* pts = points.data();
  size_t i = 0;
  double vector_sum = 0;
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveAvx2()) {
    vector_sum = SumLowerBoundsAvx2<kNegX, kNegY, kTurn>(
        pts, n, dt, table, mask, half, bias, shift, size, &i);
  }
#endif
  auto one = [&](const PointQ& p) {
    const int fx = kNegX ? -static_cast<int>(p.x) : p.x;
    const int fy = kNegY ? -static_cast<int>(p.y) : p.y;
    const int x = kTurn ? -fy : fx;
    const int y = kTurn ? fx : fy;
    const float off = table[(((y + half) & mask) << shift) | ((x + half) & mask)];
    const float d = static_cast<float>(dt[((y + bias) >> shift) * size + ((x + bias) >> shift)]) *
                    (1.0f / kUnitsPerPx);
    return std::max(0.0f, d - off);
  };
  for (; i + 4 <= n; i += 4) {
    acc[0] += one(pts[i]);
    acc[1] += one(pts[i + 1]);
    acc[2] += one(pts[i + 2]);
    acc[3] += one(pts[i + 3]);
  }
  for (; i < n; ++i) acc[0] += one(pts[i]);
  return vector_sum + (static_cast<double>(acc[0]) + acc[1]) +
         (static_cast<double>(acc[2]) + acc[3]);
}

double DistanceGrid::SumLowerBoundsFast(std::span<const PointQ> points,
                                        GridFlip flip,
                                        bool turned) const {
  switch (flip) {
    case GridFlip::kNone:
      return turned ? SumLowerBoundsFastImpl<false, false, true>(points)
                    : SumLowerBoundsFastImpl<false, false, false>(points);
    case GridFlip::kX:
      return turned ? SumLowerBoundsFastImpl<true, false, true>(points)
                    : SumLowerBoundsFastImpl<true, false, false>(points);
    case GridFlip::kY:
      return turned ? SumLowerBoundsFastImpl<false, true, true>(points)
                    : SumLowerBoundsFastImpl<false, true, false>(points);
    case GridFlip::kXY:
      return turned ? SumLowerBoundsFastImpl<true, true, true>(points)
                    : SumLowerBoundsFastImpl<true, true, false>(points);
  }
  return 0;
}

double DistanceGrid::MeanLowerBoundMargin(size_t n, double mean) {
  // Float accumulation of n non-negative terms: relative error <= n * 2^-24, doubled for
  // safety; each term's own float rounding (DT, table, subtraction) is below 1e-6 px absolute.
  return mean * (static_cast<double>(n) + 4.0) * 1.2e-7 + 1e-5;
}

}  // namespace handdb
