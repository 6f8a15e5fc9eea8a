// The search's cheap exact lower bound of the query -> view term A, before any kd-tree
// (issue 15; the proof in docs/query.md).
//
// The first bound (query/distance_transform.h) is on the view -> query term B. For the rolled
// query Q_r with n_r(c) points in coarse cell c (format/coarse_field.h; points off the grid
// count 0, always valid):
//
//   A(v, r) = mean_q d(q, Y_v) >= sum_c n_r(c) F_v(c) / |Q_r|  =: L_A(v, r)
//
// valid for every roll, and a short dot product over the cells the query occupies (a hand's ~600
// points occupy ~150-250 of the 1,849 cells).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "format/coarse_field.h"
#include "format/view.h"

namespace handdb {

class Database;

// Every view's coarse field: its shard's own (format v1.1, zero-copy) where the shard has the
// section, else computed from the points, in parallel (~110 us per view).
class CoarseFields {
 public:
  CoarseFields() = default;
  CoarseFields(const Database& db, int num_threads);
  const uint8_t* field(view_id_t v) const { return fields_[v]; }
  bool empty() const { return fields_.empty(); }
  size_t computed_bytes() const { return computed_.size(); }  // 0: all read from the shards

 private:
  std::vector<const uint8_t*> fields_;  // per view
  std::vector<uint8_t> computed_;       // storage when the shards have none
};

// The rolled query's occupied cells and their point counts.
class CellHistogram {
 public:
  void Build(std::span<const PointQ> points);
  // L_A in px: sum_c n(c) F(c) / |Q| / 2, rounded down by a relative 1e-12 (so it never exceeds
  // the exact value), given the number of query points.
  double LowerBound(const uint8_t* field, size_t num_query_points) const {
    uint64_t sum = 0;
    for (size_t i = 0; i < cells_.size(); ++i) {
      sum += static_cast<uint64_t>(counts_[i]) * field[cells_[i]];
    }
    return static_cast<double>(sum) / CoarseGrid::kValueUnitsPerPx /
           static_cast<double>(num_query_points) * (1 - 1e-12);
  }
  size_t num_cells() const { return cells_.size(); }

 private:
  std::vector<uint16_t> cells_;
  std::vector<uint32_t> counts_;
};

}  // namespace handdb
