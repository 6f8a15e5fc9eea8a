// The normalised frame shards store (docs/conventions.md, docs/conversion.md): translate so the
// area centroid of the silhouette's convex hull is the origin, scale so the silhouette's diameter
// is exactly kNormalisedDiameter (192 px), quantise to PointQ (1/16 px). The diameter is the
// largest distance between two contour points (the silhouette edge pixel centres), found with a
// convex hull and rotating calipers in O(n log n), in exact integer arithmetic. Both need only the
// contour's extreme points, so a query's edge pixels normalise the same way.
#pragma once

#include <array>
#include <span>
#include <vector>

#include "base/status.h"
#include "edges/edges.h"
#include "format/view.h"

namespace handdb {

struct Normalisation {
  // Rendered pixel coordinates (pixel centres at integer + 0.5).
  double centre_x = 0;
  double centre_y = 0;
  double diameter = 0;  // rendered px
  double scale = 0;     // normalised px per rendered px = kNormalisedDiameter / diameter
  EdgePixel end_a{};    // the diameter's end points (pixels); the centre is the hull's centroid
  EdgePixel end_b{};
};

// Convex hull of integer points (counter-clockwise in a y-up sense, no collinear points,
// starting at the lexicographically smallest (col, row)). Exposed for tests.
std::vector<EdgePixel> ConvexHull(std::span<const EdgePixel> points);

// kNoHand when the contour has fewer than two distinct points.
Result<Normalisation> ComputeNormalisation(std::span<const EdgePixel> contour);

// Pixel centres -> canonical PointQ, deduplicated. Input in raster order gives output sorted by
// (y, x) (the map is a positive scale plus a translation).
std::vector<PointQ> NormalisePixels(std::span<const EdgePixel> pixels, const Normalisation& norm);

// A keypoint (u, v, depth), rendered px (depth in px from the look-at plane) -> normalised px.
std::array<float, 3> NormaliseKeypoint(const std::array<double, 3>& keypoint_px,
                                       const Normalisation& norm);

}  // namespace handdb
