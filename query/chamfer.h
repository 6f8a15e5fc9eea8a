// The chamfer distance of docs/query.md "The distance", exactly, on the fixed-point grid (1/16 px).
//
// For a query X (px, normalised frame) and the virtual view (v, r) = canonical points Y_v rolled
// by a = 2*pi*r/R, both terms are computed in the canonical frame of the view: the query is
// rotated by -a and rounded to the PointQ grid, Q_r = round16(rot(-a) X), and
//
//   A = mean_{q in Q_r} min_{y in Y_v} |q - y|     (query -> view)
//   B = mean_{y in Y_v} min_{q in Q_r} |y - q|     (view -> query)
//   D_c = A + B                                     (px)
//
// Rotating the query instead of each view point is equivalent up to that final 1/32 px rounding
// (distances are rotation invariant), lets one rotated query serve every view, and puts both
// point sets on the same integer grid, so every distance is computed exactly (int64 squared
// distances, correctly rounded sqrt) and results do not depend on the kd-tree backend.
#pragma once

#include <span>
#include <vector>

#include "format/roll.h"
#include "format/view.h"
#include "query/kdtree.h"

namespace handdb {

// Rotates px points by `angle` (the roll convention of docs/conventions.md) and rounds them to
// PointQ (round half away from zero, clamped to the int16 range).
std::vector<PointQ> RotateAndQuantise(std::span<const Point2f> points_px, float angle);
// Rounds px points to PointQ without rotation.
std::vector<PointQ> Quantise(std::span<const Point2f> points_px);

struct ChamferTerms {
  double a = 0;  // query -> view, px
  double b = 0;  // view -> query, px
  double total() const { return a + b; }
};

// Mean over `from` of the distance (px) to the nearest point of `to_tree`.
double MeanNearestDistance(std::span<const PointQ> from, const KdTree& to_tree);

// D_c between query Q (already in the view's frame) and view Y, given kd-trees over both.
ChamferTerms Chamfer(std::span<const PointQ> query,
                     const KdTree& query_tree,
                     std::span<const PointQ> view,
                     const KdTree& view_tree);

// The same without kd-trees: O(|Q| |Y|) brute force, the reference the trees are tested against.
ChamferTerms ChamferBruteForce(std::span<const PointQ> query, std::span<const PointQ> view);

// Coordinates up to this magnitude (PointQ units, 1023.9 px) keep every squared distance of
// NearestSquaredSmall below 2^31.
constexpr int kSmallCoordLimit = 16383;

// Exact squared distance (PointQ units^2) from q to its nearest point of `points` by a linear
// scan in 32-bit integers (AVX2 when the CPU has it): cheaper than building a kd-tree when only
// a few points are asked. Requires non-empty `points` and |coordinates| <= kSmallCoordLimit for
// q and every point.
int32_t NearestSquaredSmall(PointQ q, std::span<const PointQ> points);

}  // namespace handdb
