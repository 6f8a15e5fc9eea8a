#include "pose/fit_silhouette.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <unordered_set>
#include <utility>

#include "query/distance_transform.h"

namespace handdb {
namespace {

// The WebXR generic hand's wrist-to-middle-knuckle length, the unit its radii were measured in.
constexpr double kAssetWristToMiddleKnuckle = 0.0917;

struct CapsuleRow {
  int from, to;
  double radius;
  bool outline;
};
// docs/decisions/0016: median vertex distance per link, asset units.
constexpr CapsuleRow kCapsules[] = {
    {1, 2, 0.0173, true},   {2, 3, 0.0101, true},   {3, 4, 0.0089, true},   {5, 6, 0.0098, true},
    {6, 7, 0.0081, true},   {7, 8, 0.0074, true},   {9, 10, 0.0099, true},  {10, 11, 0.0080, true},
    {11, 12, 0.0078, true}, {13, 14, 0.0088, true}, {14, 15, 0.0074, true}, {15, 16, 0.0073, true},
    {17, 18, 0.0077, true}, {18, 19, 0.0069, true}, {19, 20, 0.0063, true}, {0, 5, 0.0167, false},
    {0, 9, 0.0167, false},  {0, 13, 0.0167, false}, {0, 17, 0.0167, false}, {5, 17, 0.0167, false},
    {0, 1, 0.0167, false},
};

Status SilhouetteError(const std::string& message) {
  return Status(StatusCode::kInvalidArgument, "silhouette: " + message);
}

// The cells of a grid the outline encloses: the outline's cells and their 8 neighbours block a
// 4-connected flood from the grid's border; what the flood does not reach, less its outer ring
// of cells (the band the neighbours added), is the region.
std::vector<uint8_t> EnclosedCells(std::span<const Point2f> outline,
                                   double origin,
                                   double cell,
                                   int size) {
  const size_t n = static_cast<size_t>(size) * size;
  std::vector<uint8_t> wall(n, 0);
  for (const Point2f& p : outline) {
    const int ix = static_cast<int>(std::floor((p.x - origin) / cell));
    const int iy = static_cast<int>(std::floor((p.y - origin) / cell));
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int x = ix + dx, y = iy + dy;
        if (x >= 0 && y >= 0 && x < size && y < size) wall[static_cast<size_t>(y) * size + x] = 1;
      }
    }
  }
  std::vector<uint8_t> outside(n, 0);
  std::deque<int> queue;
  const auto push = [&](int x, int y) {
    const size_t i = static_cast<size_t>(y) * size + x;
    if (wall[i] || outside[i]) return;
    outside[i] = 1;
    queue.push_back(static_cast<int>(i));
  };
  for (int i = 0; i < size; ++i) {
    push(i, 0);
    push(i, size - 1);
    push(0, i);
    push(size - 1, i);
  }
  while (!queue.empty()) {
    const int i = queue.front();
    queue.pop_front();
    const int x = i % size, y = i / size;
    if (x > 0) push(x - 1, y);
    if (x + 1 < size) push(x + 1, y);
    if (y > 0) push(x, y - 1);
    if (y + 1 < size) push(x, y + 1);
  }
  std::vector<uint8_t> region(n, 0);
  for (int y = 1; y + 1 < size; ++y) {
    for (int x = 1; x + 1 < size; ++x) {
      const size_t i = static_cast<size_t>(y) * size + x;
      if (outside[i]) continue;
      bool next_to_outside = false;
      for (int dy = -1; dy <= 1 && !next_to_outside; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          if (outside[static_cast<size_t>(y + dy) * size + x + dx]) {
            next_to_outside = true;
            break;
          }
        }
      }
      region[i] = next_to_outside ? 0 : 1;
    }
  }
  return region;
}

PointQ ToPointQ(double x, double y) {
  return {static_cast<int16_t>(std::lround(x * kPointScale)),
          static_cast<int16_t>(std::lround(y * kPointScale))};
}

std::vector<float> NodeDistances(const DistanceGrid& grid) {
  std::vector<float> out(static_cast<size_t>(grid.size()) * grid.size());
  for (int iy = 0; iy < grid.size(); ++iy) {
    for (int ix = 0; ix < grid.size(); ++ix) {
      out[static_cast<size_t>(iy) * grid.size() + ix] = grid.NodeDistance(ix, iy);
    }
  }
  return out;
}

}  // namespace

std::vector<HandCapsule> HandCapsules(const HandRig& rig) {
  JointVector rest{};
  const HandKeypoints3d k = rig.Keypoints3d(rest);
  double length = 0;
  for (int c = 0; c < 3; ++c) length += (k[9][c] - k[0][c]) * (k[9][c] - k[0][c]);
  const double s = std::sqrt(length) / kAssetWristToMiddleKnuckle;
  std::vector<HandCapsule> out;
  for (const CapsuleRow& row : kCapsules) {
    out.push_back({row.from, row.to, row.radius * s, row.outline});
  }
  return out;
}

bool SilhouetteFieldOptions::Check() const {
  CHECK_OPTION(std::isfinite(region_cell_px) && region_cell_px >= 0.5 && region_cell_px <= 16);
  CHECK_OPTION(std::isfinite(outline_spacing_px) && outline_spacing_px > 0);
  return true;
}

Result<SilhouetteFields> MakeSilhouetteFields(std::span<const Point2f> outline,
                                              std::span<const PointQ> edges,
                                              const SilhouetteFieldOptions& options) {
  if (!options.Check()) return SilhouetteError("options fail their checks (see above)");
  if (outline.empty()) return SilhouetteError("no outline");
  if (edges.empty()) return SilhouetteError("no edge points");
  // One grid extent for both fields, so their nodes coincide: the query's frame reaches
  // +-166 px, a margin beyond the farthest point otherwise.
  double reach = 0;
  for (const Point2f& p : outline) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) return SilhouetteError("non-finite outline");
    reach = std::max({reach, std::abs(double(p.x)), std::abs(double(p.y))});
  }
  for (const PointQ& p : edges) {
    reach = std::max({reach, std::abs(double(PointQToPx(p.x))), std::abs(double(PointQToPx(p.y)))});
  }
  if (reach > 1000) return SilhouetteError("points beyond 1000 px of the normalised frame");
  const double half = std::max(170.0, std::ceil(reach) + 8);

  const double cell = options.region_cell_px;
  const int cells = static_cast<int>(std::ceil(2 * half / cell)) + 1;
  const std::vector<uint8_t> region = EnclosedCells(outline, -half, cell, cells);
  std::vector<PointQ> inside;
  // Each region cell as points a pixel apart, so the 1 px field sees the region's own edge.
  const int per_side = std::max(1, static_cast<int>(std::lround(cell)));
  for (int y = 0; y < cells; ++y) {
    for (int x = 0; x < cells; ++x) {
      if (!region[static_cast<size_t>(y) * cells + x]) continue;
      for (int sy = 0; sy < per_side; ++sy) {
        for (int sx = 0; sx < per_side; ++sx) {
          inside.push_back(ToPointQ(-half + (x + (sx + 0.5) / per_side) * cell,
                                    -half + (y + (sy + 0.5) / per_side) * cell));
        }
      }
    }
  }
  if (inside.empty()) return SilhouetteError("the outline encloses no region");

  DistanceGridOptions grid_options;
  grid_options.cell_px = 1.0f;
  grid_options.min_half_extent_px = static_cast<float>(half);
  DistanceGrid hand_grid(grid_options);
  hand_grid.Build(inside);
  DistanceGrid edge_grid(grid_options);
  edge_grid.Build(edges);
  THROW_CHECK_EQ(hand_grid.size(), edge_grid.size());

  SilhouetteFields out;
  out.size = hand_grid.size();
  out.cell_px = hand_grid.cell_px();
  out.origin_px = -hand_grid.half_extent_px();
  out.outside_hand = NodeDistances(hand_grid);
  out.edges = NodeDistances(edge_grid);
  std::unordered_set<int64_t> taken;
  for (const Point2f& p : outline) {
    const int64_t cx = static_cast<int64_t>(std::floor(p.x / options.outline_spacing_px));
    const int64_t cy = static_cast<int64_t>(std::floor(p.y / options.outline_spacing_px));
    if (taken.insert(cx * 1000003 + cy).second) out.outline.push_back(p);
  }
  return out;
}

std::vector<ProjectedCapsule> ProjectCapsules(const std::vector<HandCapsule>& capsules,
                                              const HandKeypoints3d& keypoints_in_hand,
                                              const Mat3d& cam_from_hand,
                                              const Vec3d& look_at,
                                              double scale,
                                              const std::array<double, 2>& shift) {
  const auto project = [&](int k) {
    const Vec3d& p = keypoints_in_hand[k];
    double xy[2];
    for (int r = 0; r < 2; ++r) {
      xy[r] = cam_from_hand[r][0] * (p[0] - look_at[0]) +
              cam_from_hand[r][1] * (p[1] - look_at[1]) + cam_from_hand[r][2] * (p[2] - look_at[2]);
    }
    return Point2f{static_cast<float>(scale * xy[0] + shift[0]),
                   static_cast<float>(scale * xy[1] + shift[1])};
  };
  std::vector<ProjectedCapsule> out;
  out.reserve(capsules.size());
  for (const HandCapsule& c : capsules) {
    out.push_back({project(c.from), project(c.to), c.radius * scale});
  }
  return out;
}

}  // namespace handdb
