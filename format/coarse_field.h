// Coarse distance fields of canonical views: the data behind the search's query -> view bound
// (query/coarse_bound.h, docs/query.md), stored per view in a shard section since format v1.1
// (docs/format.md) so a search need not compute them on open.
//
//   A square grid of cells of side s (8 px) over [-W, W)^2 (W = 172 px, which contains every
//   normalised view: 166.3 px of the origin at most). Cell c holds
//   F_v(c) = min over the view's points y of the distance from y to the closed box of c,
//   rounded down to a multiple of 1/2 px (saturating at 127.5 px): one byte per cell,
//   43 x 43 = 1,849 bytes per view, row-major (y rows).
//
// For every point q in cell c, d(q, Y_v) >= F_v(c): the box contains q.
//
// F_v is computed exactly in integers: per band of cells, the lower envelope of the parabolas
// (a - p.a)^2 + gap_b(p)^2 over the view's points (Felzenszwalb & Huttenlocher, exact fractions)
// evaluated at the cell edges gives the squared distance to every point on either side of a cell;
// the points inside the cell's range give gap_b^2. ~110 us per view of 600 points.
#pragma once

#include <cstdint>
#include <span>

#include "format/view.h"

namespace handdb {

struct CoarseGrid {
  static constexpr int kCellUnits = 128;                     // 8 px in PointQ units
  static constexpr int kSide = 43;                           // cells per side
  static constexpr int kHalfUnits = kSide * kCellUnits / 2;  // 2752 units = 172 px
  static constexpr int kCells = kSide * kSide;               // bytes per view
  static constexpr double kValueUnitsPerPx = 2.0;            // F in 1/2 px
  // The cell of a point, or -1 outside the grid.
  static int CellOf(PointQ p) {
    const int ix = (static_cast<int>(p.x) + kHalfUnits) >> 7;
    const int iy = (static_cast<int>(p.y) + kHalfUnits) >> 7;
    if (static_cast<unsigned>(ix) >= static_cast<unsigned>(kSide) ||
        static_cast<unsigned>(iy) >= static_cast<unsigned>(kSide)) {
      return -1;
    }
    return iy * kSide + ix;
  }
};
static_assert((1 << 7) == CoarseGrid::kCellUnits);

// F_v for one view (kCells bytes, row-major), written to `out`. Empty views get all zeros.
void ComputeCoarseField(std::span<const PointQ> view, uint8_t* out);

// Where a cell's centre is from its lower corner, in PointQ units along each axis (4 px).
constexpr int kCentreOffset = CoarseGrid::kCellUnits / 2;

// The centre field C_v, not stored in shards: per cell the distance from the cell's centre
// point to the view's nearest point, rounded down to 1/2 px (saturating at 127.5 px), row-major
// like F_v. For any point q, d(q, Y_v) >= C_v(c) - |q - centre(c)| for every cell c (distance to
// a set is 1-Lipschitz). The exact search computes it from the points when it opens a database
// (query/coarse_bound.h; ~60 us per view, the envelope of F_v over one parabola per row of points).
// Empty views get all zeros.
void ComputeCentreField(std::span<const PointQ> view, uint8_t* out);

// The exact min over the view's points of the squared distance (PointQ units^2) to the centre
// of cell (ix, iy): the brute-force reference ComputeCentreField is tested against.
int64_t CentreDistanceSquaredBruteForce(std::span<const PointQ> view, int ix, int iy);

// The exact min over the view's points of the squared distance (PointQ units^2) to the closed box
// of cell (ix, iy): the brute-force reference ComputeCoarseField is tested against.
int64_t CoarseCellDistanceSquaredBruteForce(std::span<const PointQ> view, int ix, int iy);

}  // namespace handdb
