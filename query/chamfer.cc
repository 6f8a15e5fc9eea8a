#include "query/chamfer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace handdb {
namespace {

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

ChamferTerms ChamferBruteForce(std::span<const PointQ> query, std::span<const PointQ> view) {
  return {MeanNearestBruteForce(query, view), MeanNearestBruteForce(view, query)};
}

}  // namespace handdb
