#include "query/point_buckets.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "base/status.h"
#include "format/coarse_field.h"
#include "query/chamfer.h"

namespace handdb {
namespace {

constexpr int kSide = CoarseGrid::kSide;
constexpr int kCell = CoarseGrid::kCellUnits;
constexpr int kHalf = CoarseGrid::kHalfUnits;
constexpr int32_t kNone = std::numeric_limits<int32_t>::max();

// The nearest squared distance over points [begin, end), kNone if the range is empty.
int32_t ScanRange(PointQ q, const PointQ* points, uint32_t begin, uint32_t end) {
  if (begin >= end) return kNone;
  return NearestSquaredSmall(q, std::span<const PointQ>(points + begin, end - begin));
}

}  // namespace

bool PointBuckets::Build(std::span<const PointQ> points) {
  THROW_CHECK(!points.empty());
  usable_ = false;
  start_.assign(CoarseGrid::kCells + 1, 0);
  for (const PointQ& p : points) {
    const int c = CoarseGrid::CellOf(p);
    if (c < 0 || std::abs(static_cast<int>(p.x)) > kSmallCoordLimit ||
        std::abs(static_cast<int>(p.y)) > kSmallCoordLimit) {
      return false;
    }
    ++start_[static_cast<size_t>(c) + 1];
  }
  for (size_t c = 0; c < CoarseGrid::kCells; ++c) start_[c + 1] += start_[c];
  sorted_.resize(points.size());
  // Scatter with a moving cursor per cell (start_[c] is restored afterwards).
  for (const PointQ& p : points) sorted_[start_[static_cast<size_t>(CoarseGrid::CellOf(p))]++] = p;
  for (size_t c = CoarseGrid::kCells; c > 0; --c) start_[c] = start_[c - 1];
  start_[0] = 0;
  usable_ = true;
  return true;
}

int32_t PointBuckets::NearestSquared(PointQ q) const {
  THROW_CHECK(usable_);
  const PointQ* pts = sorted_.data();
  const int ux = static_cast<int>(q.x) + kHalf;
  const int uy = static_cast<int>(q.y) + kHalf;
  const int ix = ux >> 7;
  const int iy = uy >> 7;
  static_assert(kCell == 1 << 7);
  if (ux < 0 || uy < 0 || ix >= kSide || iy >= kSide) {
    return ScanRange(q, pts, 0, static_cast<uint32_t>(sorted_.size()));
  }
  const int fx = ux - ix * kCell;
  const int fy = uy - iy * kCell;
  // q's distance to its own cell's border (units).
  const int64_t e = std::min({fx, kCell - fx, fy, kCell - fy});
  int32_t best = kNone;
  for (int k = 1; k <= 2; ++k) {
    const int x0 = std::max(ix - k, 0);
    const int x1 = std::min(ix + k, kSide - 1);
    for (int y = std::max(iy - k, 0); y <= std::min(iy + k, kSide - 1); ++y) {
      const size_t row = static_cast<size_t>(y) * kSide;
      best = std::min(best, ScanRange(q, pts, start_[row + x0], start_[row + x1 + 1]));
    }
    const int64_t reach = static_cast<int64_t>(k) * kCell + e;
    if (best != kNone && best <= reach * reach) return best;
  }
  return std::min(best, ScanRange(q, pts, 0, static_cast<uint32_t>(sorted_.size())));
}

double PointBuckets::SumNearestDistances(std::span<const PointQ> queries,
                                         double stop_above,
                                         bool* stopped) const {
  double sum = 0;
  if (stopped != nullptr) *stopped = false;
  for (const PointQ& q : queries) {
    sum += std::sqrt(static_cast<double>(NearestSquared(q))) / static_cast<double>(kPointScale);
    if (sum > stop_above) {
      if (stopped != nullptr) *stopped = true;
      return sum;
    }
  }
  return sum;
}

}  // namespace handdb
