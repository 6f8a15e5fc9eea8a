#include "query/chamfer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "base/status.h"
#include "query/simd.h"

namespace handdb {
namespace {

#ifdef HANDDB_HAVE_AVX2_PATH
// Eight points per step: unpack int16 x/y to int32, squared distance, running minimum. Returns
// the minimum over the first n - n % 8 points (INT32_MAX if none); *done receives that count.
__attribute__((target("avx2"))) int32_t NearestSquaredAvx2(PointQ q,
                                                           const PointQ* pts,
                                                           size_t n,
                                                           size_t* done) {
  static_assert(sizeof(PointQ) == 4);
  const __m256i qx = _mm256_set1_epi32(q.x);
  const __m256i qy = _mm256_set1_epi32(q.y);
  __m256i best = _mm256_set1_epi32(std::numeric_limits<int32_t>::max());
  size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256i v = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(pts + i));
    const __m256i dx = _mm256_sub_epi32(_mm256_srai_epi32(_mm256_slli_epi32(v, 16), 16), qx);
    const __m256i dy = _mm256_sub_epi32(_mm256_srai_epi32(v, 16), qy);
    const __m256i d2 = _mm256_add_epi32(_mm256_mullo_epi32(dx, dx), _mm256_mullo_epi32(dy, dy));
    best = _mm256_min_epi32(best, d2);
  }
  alignas(32) int32_t lanes[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(lanes), best);
  *done = i;
  return *std::min_element(lanes, lanes + 8);
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
  int32_t best = std::numeric_limits<int32_t>::max();
  size_t i = 0;
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveAvx2()) best = NearestSquaredAvx2(q, points.data(), points.size(), &i);
#endif
  for (; i < points.size(); ++i) {
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
