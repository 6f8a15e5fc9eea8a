// The index's embedding of views and rolled queries (docs/index.md): an approximate
// chamfer distance written as one inner product.
//
// On a square grid of `side` x `side` cells of `cell_units` (8 px by default) centred on the
// origin, a point set X has
//   h_X(c) = |X in c| / |X|        its normalised cell histogram (points off the grid are counted
//                                  in the nearest border cell), and
//   G_X(c) = min_{x in X} |o_c - x|  the exact distance from the cell's centre o_c to X (px).
// For a rolled query Q_r and a view Y_v,
//   A(v, r) ~ sum_c h_Q(c) G_Y(c),   B(v, r) ~ sum_c h_Y(c) G_Q(c)
// (each point's distance replaced by its cell centre's: 1-Lipschitz, so off by at most half a
// cell diagonal per point), and so D_c(v, r) ~ <u(Q_r), e(Y_v)> with e(Y) = [G_Y ; w h_Y] and
// u(Q) = [h_Q ; G_Q / w] for any w > 0. It is not a bound: the index ranks pairs by a
// low-dimensional projection of it and the exact search refines the best (docs/index.md has the
// measurements that chose it over the coarse lower bounds).
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "format/view.h"

namespace handdb {

struct EmbeddingGrid {
  int cell_units = 128;  // cell side in PointQ units (1/16 px): 128 = 8 px
  int side = 31;         // cells per side (odd: one cell is centred on the origin)
  int cells() const { return side * side; }
  int dims() const { return 2 * cells(); }
  bool Check(std::string* error) const;
  // The cell of p, clamped to the grid (row-major, y rows).
  int ClampedCell(PointQ p) const;
  // Centre of column (or row) i, PointQ units.
  int Centre(int i) const { return (2 * i + 1 - side) * cell_units / 2; }
};

// G_X: exact distances (px) from every cell centre to `points` (non-empty), into out[cells].
void CentreDistances(const EmbeddingGrid& grid, std::span<const PointQ> points, float* out);
// h_X into out[cells]; all zero for an empty set.
void NormalisedHistogram(const EmbeddingGrid& grid, std::span<const PointQ> points, float* out);

// e(Y) = [G_Y ; w h_Y] into out[dims].
void ViewVector(const EmbeddingGrid& grid, std::span<const PointQ> points, float w, float* out);
// u(Q) = [h_Q ; G_Q / w] into out[dims].
void QueryVector(const EmbeddingGrid& grid, std::span<const PointQ> points, float w, float* out);

}  // namespace handdb
