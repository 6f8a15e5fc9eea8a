#include "query/coarse_bound.h"

#include "base/thread_pool.h"
#include "query/database.h"

namespace handdb {

CoarseFields::CoarseFields(const Database& db, int num_threads) {
  const size_t n = db.num_views();
  fields_.resize(n);
  std::vector<view_id_t> missing;  // views whose shard has no coarse-fields section
  for (size_t v = 0; v < n; ++v) {
    fields_[v] = db.coarse_field(static_cast<view_id_t>(v));
    if (fields_[v] == nullptr) missing.push_back(static_cast<view_id_t>(v));
  }
  computed_.resize(missing.size() * static_cast<size_t>(CoarseGrid::kCells));
  ParallelFor(missing.size(), ResolveNumThreads(num_threads), [&](size_t i, int) {
    ComputeCoarseField(db.points(missing[i]), computed_.data() + i * CoarseGrid::kCells);
    return true;
  });
  for (size_t i = 0; i < missing.size(); ++i) {
    fields_[missing[i]] = computed_.data() + i * CoarseGrid::kCells;
  }
}

void CellHistogram::Build(std::span<const PointQ> points) {
  std::vector<uint32_t> count(CoarseGrid::kCells, 0);
  for (const PointQ& p : points) {
    const int c = CoarseGrid::CellOf(p);
    if (c >= 0) ++count[static_cast<size_t>(c)];
  }
  cells_.clear();
  counts_.clear();
  for (int c = 0; c < CoarseGrid::kCells; ++c) {
    if (count[static_cast<size_t>(c)] == 0) continue;
    cells_.push_back(static_cast<uint16_t>(c));
    counts_.push_back(count[static_cast<size_t>(c)]);
  }
}

}  // namespace handdb
