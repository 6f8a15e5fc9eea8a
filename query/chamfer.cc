#include "query/chamfer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "base/status.h"
#include "query/simd.h"

namespace handdb {
namespace {

#ifdef HANDDB_HAVE_AVX2_PATH
// Eight points per step, each point's (x, y) an int16 pair: their differences from q fit int16
// (|coordinates| <= kSmallCoordLimit), so one multiply-add of the pairs gives dx^2 + dy^2 in
// int32 (below 2^31), then a running minimum; the last n % 8 points are read with a masked load.
// Returns the minimum over all n points (n >= 1).
__attribute__((target("avx2"))) int32_t NearestSquaredAvx2(PointQ q, const PointQ* pts, size_t n) {
  static_assert(sizeof(PointQ) == 4);
  int32_t q_pair = 0;
  std::memcpy(&q_pair, &q, sizeof(q_pair));
  const __m256i qv = _mm256_set1_epi32(q_pair);
  const __m256i none = _mm256_set1_epi32(std::numeric_limits<int32_t>::max());
  __m256i best0 = none;
  __m256i best1 = none;
  size_t i = 0;
  for (; i + 16 <= n; i += 16) {
    const __m256i d0 =
        _mm256_sub_epi16(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(pts + i)), qv);
    const __m256i d1 =
        _mm256_sub_epi16(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(pts + i + 8)), qv);
    best0 = _mm256_min_epi32(best0, _mm256_madd_epi16(d0, d0));
    best1 = _mm256_min_epi32(best1, _mm256_madd_epi16(d1, d1));
  }
  if (i + 8 <= n) {
    const __m256i d =
        _mm256_sub_epi16(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(pts + i)), qv);
    best0 = _mm256_min_epi32(best0, _mm256_madd_epi16(d, d));
    i += 8;
  }
  if (i < n) {
    // Lanes past the end are neither read nor counted.
    const __m256i lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256i mask = _mm256_cmpgt_epi32(_mm256_set1_epi32(static_cast<int>(n - i)), lanes);
    const __m256i v = _mm256_maskload_epi32(reinterpret_cast<const int*>(pts + i), mask);
    const __m256i d = _mm256_sub_epi16(v, qv);
    best1 = _mm256_min_epi32(best1, _mm256_blendv_epi8(none, _mm256_madd_epi16(d, d), mask));
  }
  const __m256i best = _mm256_min_epi32(best0, best1);
  __m128i m = _mm_min_epi32(_mm256_castsi256_si128(best), _mm256_extracti128_si256(best, 1));
  m = _mm_min_epi32(m, _mm_shuffle_epi32(m, _MM_SHUFFLE(1, 0, 3, 2)));
  m = _mm_min_epi32(m, _mm_shuffle_epi32(m, _MM_SHUFFLE(2, 3, 0, 1)));
  return _mm_cvtsi128_si32(m);
}

#endif

int16_t RoundToQ(float v_px) {
  const double u = std::round(static_cast<double>(v_px) * kPointScale);
  return static_cast<int16_t>(std::clamp(u,
                                         static_cast<double>(std::numeric_limits<int16_t>::min()),
                                         static_cast<double>(std::numeric_limits<int16_t>::max())));
}

double MeanNearestBruteForce(std::span<const PointQ> from, std::span<const PointQ> to) {
  if (from.empty() || to.empty()) return 0;
  double sum = 0;
  for (const PointQ& p : from) {
    int64_t best = std::numeric_limits<int64_t>::max();
    for (const PointQ& q : to) best = std::min(best, SquaredDistanceQ(p, q));
    sum += std::sqrt(static_cast<double>(best)) / static_cast<double>(kPointScale);
  }
  return sum / static_cast<double>(from.size());
}

}  // namespace

std::vector<PointQ> RotateAndQuantise(std::span<const Point2f> points_px, float angle) {
  std::vector<PointQ> out(points_px.size());
  const double c = std::cos(static_cast<double>(angle));
  const double s = std::sin(static_cast<double>(angle));
  for (size_t i = 0; i < points_px.size(); ++i) {
    const double x = points_px[i].x;
    const double y = points_px[i].y;
    out[i] = {RoundToQ(static_cast<float>(c * x - s * y)),
              RoundToQ(static_cast<float>(s * x + c * y))};
  }
  return out;
}

std::vector<PointQ> Quantise(std::span<const Point2f> points_px) {
  std::vector<PointQ> out(points_px.size());
  for (size_t i = 0; i < points_px.size(); ++i) {
    out[i] = {RoundToQ(points_px[i].x), RoundToQ(points_px[i].y)};
  }
  return out;
}

double MeanNearestDistance(std::span<const PointQ> from, const KdTree& to_tree) {
  if (from.empty()) return 0;
  return to_tree.SumNearestDistances(from, std::numeric_limits<double>::infinity()) /
         static_cast<double>(from.size());
}

ChamferTerms Chamfer(std::span<const PointQ> query,
                     const KdTree& query_tree,
                     std::span<const PointQ> view,
                     const KdTree& view_tree) {
  return {MeanNearestDistance(query, view_tree), MeanNearestDistance(view, query_tree)};
}

int32_t NearestSquaredSmall(PointQ q, std::span<const PointQ> points) {
  THROW_CHECK(!points.empty());
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveAvx2()) return NearestSquaredAvx2(q, points.data(), points.size());
#endif
  int32_t best = std::numeric_limits<int32_t>::max();
  for (size_t i = 0; i < points.size(); ++i) {
    const int32_t dx = static_cast<int32_t>(points[i].x) - q.x;
    const int32_t dy = static_cast<int32_t>(points[i].y) - q.y;
    best = std::min(best, dx * dx + dy * dy);
  }
  return best;
}

ChamferTerms ChamferBruteForce(std::span<const PointQ> query, std::span<const PointQ> view) {
  return {MeanNearestBruteForce(query, view), MeanNearestBruteForce(view, query)};
}

}  // namespace handdb
