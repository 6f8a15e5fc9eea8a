// Exact 2-D nearest-neighbour search over fixed-point points (PointQ, units of 1/16 px), behind
// one small interface with two interchangeable backends: nanoflann (default, an adaptor over the
// caller's storage, no copy) and PCL's KdTreeFLANN (copies into a pcl::PointCloud, in a plugin
// opened on first use). Neither library appears in this header.
//
// Distances: NearestSquared() returns the EXACT squared distance in PointQ units^2 (1/256 px^2),
// recomputed in 64-bit integers from the neighbour the backend found, so both backends return
// identical values (ties may pick different indices, never different distances). The sums return
// plain (not squared) distances in px.
//
// A built tree is immutable; all queries are const and safe from many threads at once.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string_view>

#include "base/status.h"
#include "format/view.h"

namespace handdb {

enum class KdTreeBackend { kNanoflann, kPcl };

// "nanoflann" / "pcl".
std::string_view KdTreeBackendName(KdTreeBackend backend);
Result<KdTreeBackend> ParseKdTreeBackend(std::string_view name);
// PCL's backend lives in a plugin (query/kdtree_pcl_plugin.h) opened on the first tree that uses
// it; this opens it now, so a command can say once that it is missing (kNotFound naming where it
// looked) instead of failing at the first tree, which throws. Nothing to load for nanoflann.
Status LoadKdTreeBackend(KdTreeBackend backend);

class KdTree {
 public:
  // `points` must be non-empty and must outlive the tree (nanoflann reads them in place).
  KdTree(std::span<const PointQ> points, KdTreeBackend backend);
  ~KdTree();
  KdTree(const KdTree&) = delete;
  KdTree& operator=(const KdTree&) = delete;
  KdTree(KdTree&&) noexcept;
  KdTree& operator=(KdTree&&) noexcept;

  // Exact squared distance (PointQ units^2) from `q` to its nearest tree point; `index` (optional)
  // receives one nearest point.
  int64_t NearestSquared(PointQ q, uint32_t* index = nullptr) const;

  // Sum over `queries` of the distance (px) to the nearest tree point, accumulated in order in
  // double. Stops as soon as the partial sum exceeds `stop_above` (then *stopped = true and the
  // partial sum is returned); pass +infinity to never stop.
  double SumNearestDistances(std::span<const PointQ> queries,
                             double stop_above,
                             bool* stopped = nullptr) const;

  size_t size() const { return points_.size(); }
  KdTreeBackend backend() const { return backend_; }

  // Implementation interface (kdtree.cc); public only so the .cc can derive from it.
  struct Impl;

 private:
  std::span<const PointQ> points_;
  KdTreeBackend backend_;
  std::unique_ptr<Impl> impl_;
};

// Exact squared distance between two fixed-point points, in PointQ units^2.
inline int64_t SquaredDistanceQ(PointQ a, PointQ b) {
  const int64_t dx = static_cast<int64_t>(a.x) - b.x;
  const int64_t dy = static_cast<int64_t>(a.y) - b.y;
  return dx * dx + dy * dy;
}

}  // namespace handdb
