// Lower bounds of point-to-set distances from one exact Euclidean distance transform.
//
// A DistanceGrid holds, for a set Q of fixed-point points (PointQ, 1/16 px), the exact Euclidean
// distance transform of Q rasterised to the nodes of a square grid of step `cell_px` centred on the
// origin (Felzenszwalb & Huttenlocher's two-pass squared EDT on integer node distances, then
// floor(sqrt) stored as uint16 in units of 1/64 px, saturating: every stored value is <= the true
// node distance). It answers, for any point p,
//
//   LowerBound(p) = max(0, DT(n) - r_max - |p - n|)  <=  min_{q in Q} |p - q|
//
// where n is the grid node nearest to p and r_max the largest distance from a point of Q to its
// rasterised node. Proof: d(p, Q) >= d(n, Q) - |p - n| (1-Lipschitz) and d(n, Q) >= DT(n) - r_max.
// Points outside the grid get the exact distance to the grid's box, which bounds d(p, Q) because
// the grid is sized to contain Q. Nearest-node lookup (not bilinear): it has the same worst-case
// slack as bilinear interpolation and costs one load instead of four; |p - n| depends only on
// p's position modulo the cell, so it comes from a small table.
//
// Memory: one uint16 per node and nothing else (a 1 px grid for a normalised hand, 341 x 341 nodes,
// is 233 KB; the float transform plus OpenCV's seed image it replaced took 581 KB, and OpenCV's
// distanceTransform also paged in its library code and started its thread pool: docs/query.md).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "format/view.h"

namespace handdb {

// How a grid of the set Q is read: at p (kNone), or at p reflected in an axis or both. The grid
// of Q read at F(p) bounds d(p, F(Q)) (F is an isometry and its own inverse): rolls r and
// r + R/2 are Q and -Q (kXY), and the mirrored query's rolls are Q reflected in x or y (kX, kY),
// so one grid serves up to four (hand, roll) pairs (docs/query.md). Read turned as well (at
// T^-1(F(p)), T(x, y) = (y, -x) the quarter turn), it bounds d(p, F(T(Q))): roll r + R/4 is T of
// roll r, so with R a multiple of 4 one grid serves eight.
enum class GridFlip { kNone, kX, kY, kXY };

struct DistanceGridOptions {
  // Grid step in px: 1, 1/2, 1/4, 1/8 or 1/16 (a power-of-two fraction of a pixel, so that node
  // indices come from integer shifts of PointQ coordinates).
  float cell_px = 1.0f;
  // The grid covers at least [-min_half_extent_px, +min_half_extent_px]^2 and grows to contain
  // every point of the set. Normalised views lie within 192 * sqrt(3) / 2 = 166.3 px of the origin.
  float min_half_extent_px = 170.0f;
  bool Check() const;
};

class DistanceGrid {
 public:
  DistanceGrid() = default;
  explicit DistanceGrid(const DistanceGridOptions& options);

  // (Re)builds the grid for `points` (non-empty), reusing buffers.
  void Build(std::span<const PointQ> points);

  // Units of the stored transform: 1/64 px.
  static constexpr float kUnitsPerPx = 64.0f;
  // Distance transform value (px) at grid node (ix, iy): the exact distance rounded down to a
  // multiple of 1/64 px (saturating at 65535/64 px, far beyond any normalised hand).
  float NodeDistance(int ix, int iy) const {
    return static_cast<float>(dt_[static_cast<size_t>(iy) * size_ + ix]) / kUnitsPerPx;
  }
  // Node nearest to p (may be outside [0, size) for points off the grid).
  int NodeIndex(int coord) const { return (coord + half_extent_u_ + cell_u_ / 2) >> shift_; }
  // The lower bound of d(p, Q) in px described above; with a flip F, of d(F(p), Q), which is
  // d(p, F(Q)); `turned`, of d(T^-1(F(p)), Q) = d(p, F(T(Q))) with T^-1(x, y) = (-y, x).
  float LowerBound(PointQ p, GridFlip flip = GridFlip::kNone, bool turned = false) const;
  // Sum of LowerBound over points (float accumulation; see MeanLowerBoundMargin()).
  double SumLowerBounds(std::span<const PointQ> points,
                        GridFlip flip = GridFlip::kNone,
                        bool turned = false) const;
  // True if every point with |x|, |y| <= max_abs (PointQ units) is on the grid's fast path
  // (for p and for any flip or turn of p alike).
  bool Covers(int max_abs) const { return max_abs <= fast_limit_; }
  // SumLowerBounds for points known to satisfy Covers(); no bounds checks.
  double SumLowerBoundsFast(std::span<const PointQ> points,
                            GridFlip flip = GridFlip::kNone,
                            bool turned = false) const;

  int size() const { return size_; }
  // The grid step of the last Build (px): options' cell_px, doubled while a far point would make
  // the grid wider than 2049 nodes (up to 4 px).
  float cell_px() const { return static_cast<float>(cell_u_) / kPointScale; }
  float half_extent_px() const { return static_cast<float>(half_extent_u_) / kPointScale; }
  float r_max_px() const { return r_max_px_; }
  // Upper bound on the float rounding error of mean = SumLowerBounds*(...) / n over n points:
  // subtract it from the mean to keep the bound valid.
  static double MeanLowerBoundMargin(size_t n, double mean);

 private:
  template <bool kNegX, bool kNegY, bool kTurn>
  double SumLowerBoundsFastImpl(std::span<const PointQ> points) const;

  DistanceGridOptions options_;
  int shift_ = 4;          // log2(cell in PointQ units)
  int cell_u_ = 16;        // cell in PointQ units
  int half_extent_u_ = 0;  // grid half extent in PointQ units, a multiple of cell_u_
  int size_ = 0;           // nodes per side = 2 * half_extent_u_ / cell_u_ + 1
  int fast_limit_ = -1;    // |coord| <= this -> node index in range
  float r_max_px_ = 0;
  // DT per node (1/64 px, rounded down), row-major (y rows), plus one padding element so the
  // vector path may load 32 bits at the last node.
  std::vector<uint16_t> dt_;
  std::vector<float> offset_table_;  // r_max + |p - n| in px, by (x mod cell, y mod cell)
  // Row-pass scratch of the transform (one row each): parabola vertices and boundaries.
  std::vector<int32_t> row_f_;
  std::vector<int32_t> row_v_;
  std::vector<int64_t> row_zn_;
  std::vector<int64_t> row_zd_;
  std::vector<int32_t> row_d2_;
};

}  // namespace handdb
