#include "query/index/embedding.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "query/chamfer.h"

namespace handdb {

bool EmbeddingGrid::Check(std::string* error) const {
  if (cell_units < 16 || cell_units > 1024 || cell_units % 2 != 0) {
    *error = "embedding cell must be an even number of 1/16 px units in [16, 1024]";
    return false;
  }
  if (side < 1 || side > 101 || side % 2 == 0) {
    *error = "embedding grid side must be odd, in [1, 101]";
    return false;
  }
  return true;
}

int EmbeddingGrid::ClampedCell(PointQ p) const {
  const int half = side * cell_units / 2;
  auto index = [&](int c) {
    const int i = (c + half) >= 0 ? (c + half) / cell_units : -1;
    return std::clamp(i, 0, side - 1);
  };
  return index(p.y) * side + index(p.x);
}

void CentreDistances(const EmbeddingGrid& grid, std::span<const PointQ> points, float* out) {
  bool small = true;
  for (const PointQ& p : points) {
    small = small && std::abs(static_cast<int>(p.x)) <= kSmallCoordLimit &&
            std::abs(static_cast<int>(p.y)) <= kSmallCoordLimit;
  }
  for (int iy = 0; iy < grid.side; ++iy) {
    for (int ix = 0; ix < grid.side; ++ix) {
      const PointQ o{static_cast<int16_t>(grid.Centre(ix)), static_cast<int16_t>(grid.Centre(iy))};
      int64_t best = std::numeric_limits<int64_t>::max();
      if (small) {
        best = NearestSquaredSmall(o, points);
      } else {
        for (const PointQ& p : points) {
          const int64_t dx = int64_t{p.x} - o.x, dy = int64_t{p.y} - o.y;
          best = std::min(best, dx * dx + dy * dy);
        }
      }
      out[iy * grid.side + ix] =
          static_cast<float>(std::sqrt(static_cast<double>(best)) / kPointScale);
    }
  }
}

void NormalisedHistogram(const EmbeddingGrid& grid, std::span<const PointQ> points, float* out) {
  std::fill(out, out + grid.cells(), 0.0f);
  if (points.empty()) return;
  const float w = 1.0f / static_cast<float>(points.size());
  for (const PointQ& p : points) out[grid.ClampedCell(p)] += w;
}

void ViewVector(const EmbeddingGrid& grid, std::span<const PointQ> points, float w, float* out) {
  const int n = grid.cells();
  if (points.empty()) {
    std::fill(out, out + grid.dims(), 0.0f);
    return;
  }
  CentreDistances(grid, points, out);
  NormalisedHistogram(grid, points, out + n);
  for (int c = 0; c < n; ++c) out[n + c] *= w;
}

void QueryVector(const EmbeddingGrid& grid, std::span<const PointQ> points, float w, float* out) {
  const int n = grid.cells();
  NormalisedHistogram(grid, points, out);
  if (points.empty()) {
    std::fill(out + n, out + grid.dims(), 0.0f);
    return;
  }
  CentreDistances(grid, points, out + n);
  for (int c = 0; c < n; ++c) out[n + c] /= w;
}

}  // namespace handdb
