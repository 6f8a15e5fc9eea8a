// Exact nearest-point queries over one small point set (a view's or a rolled query's few hundred
// points) by buckets: the points sorted into the 8 px cells of the coarse grid
// (format/coarse_field.h), so the cells of one grid row are one contiguous run.
//
// A query point q in cell (ix, iy) first scans the 3 x 3 cells around it (three runs), then the
// 5 x 5, then every point: any point outside the (2k+1) x (2k+1) cells around q is at least
// k * 8 px + e from q, e being q's distance to its own cell's border, so once the nearest point
// found is that close the search is exact and stops. Exact means the same squared distance (an
// integer, PointQ units^2) a kd-tree or a full scan finds; sums are accumulated exactly like
// KdTree::SumNearestDistances, so they agree bit for bit.
//
// Building is a counting sort (~10 us for 600 points); a query costs ~3 short vectorised scans
// where a full scan reads every point (the search's linear scans, docs/query.md).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "format/view.h"

namespace handdb {

class PointBuckets {
 public:
  // Buckets `points` (non-empty). Returns false, leaving the object unusable, when a point is
  // off the coarse grid or a coordinate exceeds kSmallCoordLimit (query/chamfer.h): the caller
  // then uses a kd-tree or full scans.
  bool Build(std::span<const PointQ> points);
  bool usable() const { return usable_; }
  // Exact squared distance (PointQ units^2) from q (|coordinates| <= kSmallCoordLimit) to the
  // nearest point.
  int32_t NearestSquared(PointQ q) const;
  // As KdTree::SumNearestDistances: the sum over `queries` of the distance (px) to the nearest
  // point, in order in double, stopped once it exceeds `stop_above` (*stopped = true).
  double SumNearestDistances(std::span<const PointQ> queries,
                             double stop_above,
                             bool* stopped = nullptr) const;
  size_t size() const { return sorted_.size(); }

 private:
  std::vector<PointQ> sorted_;   // by cell, row-major
  std::vector<uint32_t> start_;  // kCells + 1: cell c's points are [start_[c], start_[c + 1])
  bool usable_ = false;
};

}  // namespace handdb
