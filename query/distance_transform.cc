#include "query/distance_transform.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <opencv2/imgproc.hpp>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define HANDDB_HAVE_AVX2_PATH 1
#endif

#include "format/status.h"

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

void DistanceGrid::Build(std::span<const PointQ> points) {
  THROW_CHECK(!points.empty());
  THROW_CHECK_GT(cell_u_, 0);
  int max_abs = static_cast<int>(std::ceil(options_.min_half_extent_px * kPointScale));
  for (const PointQ& q : points) {
    max_abs = std::max({max_abs, std::abs(static_cast<int>(q.x)), std::abs(static_cast<int>(q.y))});
  }
  half_extent_u_ = (max_abs + cell_u_ - 1) / cell_u_ * cell_u_;
  size_ = 2 * half_extent_u_ / cell_u_ + 1;
  fast_limit_ = half_extent_u_;

  // Seeds are 0, everything else non-zero: OpenCV measures the distance to the nearest zero pixel.
  seeds_.assign(static_cast<size_t>(size_) * size_, 255);
  double r_max_sq = 0;
  const double cell = cell_u_;
  for (const PointQ& q : points) {
    const int ix = NodeIndex(q.x);
    const int iy = NodeIndex(q.y);
    seeds_[static_cast<size_t>(iy) * size_ + ix] = 0;
    const double dx = q.x - (static_cast<double>(ix) * cell - half_extent_u_);
    const double dy = q.y - (static_cast<double>(iy) * cell - half_extent_u_);
    r_max_sq = std::max(r_max_sq, dx * dx + dy * dy);
  }
  r_max_px_ = static_cast<float>(std::sqrt(r_max_sq) / kPointScale);

  dt_.resize(static_cast<size_t>(size_) * size_);
  const cv::Mat src(size_, size_, CV_8UC1, seeds_.data());
  cv::Mat dst(size_, size_, CV_32FC1, dt_.data());
  cv::distanceTransform(src, dst, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
  THROW_CHECK(dst.data == reinterpret_cast<uchar*>(dt_.data()));  // written in place
  const float scale = options_.cell_px;
  for (float& d : dt_) d *= scale;

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

float DistanceGrid::LowerBound(PointQ p) const {
  const int ax = std::abs(static_cast<int>(p.x));
  const int ay = std::abs(static_cast<int>(p.y));
  if (ax > fast_limit_ || ay > fast_limit_) {
    // Off the grid: distance to the box holding every point of the set.
    const double dx = std::max(0, ax - half_extent_u_);
    const double dy = std::max(0, ay - half_extent_u_);
    return static_cast<float>(std::sqrt(dx * dx + dy * dy) / kPointScale);
  }
  const int mask = cell_u_ - 1;
  const int half = cell_u_ / 2;
  const float off = offset_table_[(((p.y + half) & mask) << shift_) | ((p.x + half) & mask)];
  return std::max(0.0f, dt_[static_cast<size_t>(NodeIndex(p.y)) * size_ + NodeIndex(p.x)] - off);
}

double DistanceGrid::SumLowerBounds(std::span<const PointQ> points) const {
  double sum = 0;
  for (const PointQ& p : points) sum += LowerBound(p);
  return sum;
}

namespace {

#ifdef HANDDB_HAVE_AVX2_PATH
__attribute__((target("avx2"), always_inline)) inline __m256 Step(const PointQ* p,
                                                                  __m256i vbias,
                                                                  __m256i vhalf,
                                                                  __m256i vmask,
                                                                  __m256i vsize,
                                                                  __m128i vshift,
                                                                  __m256 zero,
                                                                  const float* dt,
                                                                  const float* table) {
  const __m256i v = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
  const __m256i x = _mm256_srai_epi32(_mm256_slli_epi32(v, 16), 16);
  const __m256i y = _mm256_srai_epi32(v, 16);
  const __m256i ix = _mm256_sra_epi32(_mm256_add_epi32(x, vbias), vshift);
  const __m256i iy = _mm256_sra_epi32(_mm256_add_epi32(y, vbias), vshift);
  const __m256i idx = _mm256_add_epi32(_mm256_mullo_epi32(iy, vsize), ix);
  const __m256i tx = _mm256_and_si256(_mm256_add_epi32(x, vhalf), vmask);
  const __m256i ty = _mm256_and_si256(_mm256_add_epi32(y, vhalf), vmask);
  const __m256i tidx = _mm256_or_si256(_mm256_sll_epi32(ty, vshift), tx);
  const __m256 d = _mm256_i32gather_ps(dt, idx, 4);
  const __m256 off = _mm256_i32gather_ps(table, tidx, 4);
  return _mm256_max_ps(_mm256_sub_ps(d, off), zero);
}

// Eight points per step: unpack int16 x/y, compute node and offset-table indices, two gathers.
// Returns the sum over the first n - n % 8 points; *done receives that count.
__attribute__((target("avx2"))) double SumLowerBoundsAvx2(const PointQ* pts,
                                                          size_t n,
                                                          const float* dt,
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
    acc0 = _mm256_add_ps(acc0, Step(pts + i, vbias, vhalf, vmask, vsize, vshift, zero, dt, table));
    acc1 =
        _mm256_add_ps(acc1, Step(pts + i + 8, vbias, vhalf, vmask, vsize, vshift, zero, dt, table));
  }
  for (; i + 8 <= n; i += 8)
    acc0 = _mm256_add_ps(acc0, Step(pts + i, vbias, vhalf, vmask, vsize, vshift, zero, dt, table));
  alignas(32) float lanes[16];
  _mm256_store_ps(lanes, acc0);
  _mm256_store_ps(lanes + 8, acc1);
  double sum = 0;
  for (float f : lanes) sum += f;
  *done = i;
  return sum;
}

bool HaveAvx2() {
  static const bool have = __builtin_cpu_supports("avx2");
  return have;
}
#endif

}  // namespace

double DistanceGrid::SumLowerBoundsFast(std::span<const PointQ> points) const {
  const float* dt = dt_.data();
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
    vector_sum = SumLowerBoundsAvx2(pts, n, dt, table, mask, half, bias, shift, size, &i);
  }
#endif
  auto one = [&](const PointQ& p) {
    const int x = p.x;
    const int y = p.y;
    const float off = table[(((y + half) & mask) << shift) | ((x + half) & mask)];
    const float d = dt[((y + bias) >> shift) * size + ((x + bias) >> shift)];
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

double DistanceGrid::MeanLowerBoundMargin(size_t n, double mean) {
  // Float accumulation of n non-negative terms: relative error <= n * 2^-24, doubled for
  // safety; each term's own float rounding (DT, table, subtraction) is below 1e-6 px absolute.
  return mean * (static_cast<double>(n) + 4.0) * 1.2e-7 + 1e-5;
}

}  // namespace handdb
