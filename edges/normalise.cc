#include "edges/normalise.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace handdb {
namespace {

int64_t Cross(const EdgePixel& o, const EdgePixel& a, const EdgePixel& b) {
  return static_cast<int64_t>(a.col - o.col) * (b.row - o.row) -
         static_cast<int64_t>(a.row - o.row) * (b.col - o.col);
}

int64_t Dist2(const EdgePixel& a, const EdgePixel& b) {
  const int64_t dx = a.col - b.col;
  const int64_t dy = a.row - b.row;
  return dx * dx + dy * dy;
}

bool LexLess(const EdgePixel& a, const EdgePixel& b) {
  return a.col != b.col ? a.col < b.col : a.row < b.row;
}

}  // namespace

std::vector<EdgePixel> ConvexHull(std::span<const EdgePixel> points) {
  std::vector<EdgePixel> p(points.begin(), points.end());
  std::sort(p.begin(), p.end(), LexLess);
  p.erase(std::unique(p.begin(),
                      p.end(),
                      [](const EdgePixel& a, const EdgePixel& b) {
                        return a.col == b.col && a.row == b.row;
                      }),
          p.end());
  if (p.size() < 3) return p;
  // Andrew's monotone chain; pops collinear points.
  std::vector<EdgePixel> hull(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && Cross(hull[k - 2], hull[k - 1], p[i]) <= 0) --k;
    hull[k++] = p[i];
  }
  for (size_t i = p.size() - 1, lower = k + 1; i-- > 0;) {
    while (k >= lower && Cross(hull[k - 2], hull[k - 1], p[i]) <= 0) --k;
    hull[k++] = p[i];
  }
  hull.resize(k - 1);  // the last point repeats the first
  return hull;
}

Result<Normalisation> ComputeNormalisation(std::span<const EdgePixel> contour) {
  const std::vector<EdgePixel> hull = ConvexHull(contour);
  if (hull.size() < 2) {
    return Status(StatusCode::kNoHand,
                  "silhouette has " + std::to_string(hull.size()) + " distinct contour point(s)");
  }
  // Best pair: largest squared distance; ties broken by the lexicographically smallest
  // (smaller end, larger end) so the choice does not depend on the hull's start point.
  int64_t best = -1;
  EdgePixel best_a{}, best_b{};
  auto consider = [&](const EdgePixel& p, const EdgePixel& q) {
    EdgePixel a = p, b = q;
    if (LexLess(b, a)) std::swap(a, b);
    const int64_t d = Dist2(a, b);
    const bool better =
        d > best ||
        (d == best && (LexLess(a, best_a) || (!LexLess(best_a, a) && LexLess(b, best_b))));
    if (better) {
      best = d;
      best_a = a;
      best_b = b;
    }
  };
  const size_t k = hull.size();
  if (k == 2) {
    consider(hull[0], hull[1]);
  } else {
    // Rotating calipers: for each hull edge (i, i+1) advance j to the farthest vertex from the
    // edge's line; every antipodal pair is visited, including both ends of parallel edges.
    size_t j = 1;
    for (size_t i = 0; i < k; ++i) {
      const size_t ni = (i + 1) % k;
      while (Cross(hull[i], hull[ni], hull[(j + 1) % k]) > Cross(hull[i], hull[ni], hull[j])) {
        j = (j + 1) % k;
      }
      consider(hull[i], hull[j]);
      consider(hull[ni], hull[j]);
      const size_t nj = (j + 1) % k;
      if (Cross(hull[i], hull[ni], hull[nj]) == Cross(hull[i], hull[ni], hull[j])) {
        consider(hull[i], hull[nj]);
        consider(hull[ni], hull[nj]);
      }
    }
  }
  Normalisation norm;
  norm.end_a = best_a;
  norm.end_b = best_b;
  norm.diameter = std::sqrt(static_cast<double>(best));
  norm.scale = static_cast<double>(kNormalisedDiameter) / norm.diameter;
  // Centre: the area centroid of the convex hull. Like the diameter it is rotation-equivariant
  // and computable from any point set that contains the silhouette's extreme points (a query's
  // edge points too), but it moves continuously with the shape: the diameter's midpoint jumps
  // when two nearly equal diameters swap (measured: docs/conversion.md).
  double area2 = 0, cx = 0, cy = 0;
  for (size_t i = 0; i < hull.size() && hull.size() >= 3; ++i) {
    const EdgePixel& p = hull[i];
    const EdgePixel& q = hull[(i + 1) % hull.size()];
    const double cross = static_cast<double>(p.col) * q.row - static_cast<double>(q.col) * p.row;
    area2 += cross;
    cx += (p.col + q.col) * cross;
    cy += (p.row + q.row) * cross;
  }
  if (area2 != 0) {
    norm.centre_x = cx / (3.0 * area2) + 0.5;
    norm.centre_y = cy / (3.0 * area2) + 0.5;
  } else {  // collinear contour: the hull is a segment
    norm.centre_x = 0.5 * (best_a.col + best_b.col) + 0.5;
    norm.centre_y = 0.5 * (best_a.row + best_b.row) + 0.5;
  }
  return norm;
}

std::vector<PointQ> NormalisePixels(std::span<const EdgePixel> pixels, const Normalisation& norm) {
  THROW_CHECK_GT(norm.scale, 0.0);
  std::vector<PointQ> out;
  out.reserve(pixels.size());
  const double s = norm.scale * kPointScale;
  for (const EdgePixel& p : pixels) {
    const double x = std::nearbyint((p.col + 0.5 - norm.centre_x) * s);
    const double y = std::nearbyint((p.row + 0.5 - norm.centre_y) * s);
    THROW_CHECK_MSG(std::fabs(x) <= 32767 && std::fabs(y) <= 32767,
                    "normalised point out of int16 range: " << x << ", " << y);
    out.push_back({static_cast<int16_t>(x), static_cast<int16_t>(y)});
  }
  std::sort(out.begin(), out.end(), [](const PointQ& a, const PointQ& b) {
    return a.y != b.y ? a.y < b.y : a.x < b.x;
  });
  out.erase(std::unique(out.begin(),
                        out.end(),
                        [](const PointQ& a, const PointQ& b) { return a.x == b.x && a.y == b.y; }),
            out.end());
  return out;
}

std::array<float, 3> NormaliseKeypoint(const std::array<double, 3>& keypoint_px,
                                       const Normalisation& norm) {
  return {static_cast<float>((keypoint_px[0] - norm.centre_x) * norm.scale),
          static_cast<float>((keypoint_px[1] - norm.centre_y) * norm.scale),
          static_cast<float>(keypoint_px[2] * norm.scale)};
}

}  // namespace handdb
