#include "generator/sampling/view_sampler.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <tuple>
#include <utility>

#include "base/status.h"

namespace handdb {

std::vector<Eigen::Vector3d> FibonacciDirections(int n) {
  THROW_CHECK_GE(n, 1);
  const double golden_angle = M_PI * (3.0 - std::sqrt(5.0));
  std::vector<Eigen::Vector3d> out;
  out.reserve(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = golden_angle * i;
    out.emplace_back(r * std::cos(phi), r * std::sin(phi), z);
  }
  return out;
}

std::vector<Eigen::Vector3d> IcosahedronDirections(int subdivisions) {
  THROW_CHECK_MSG(subdivisions >= 0 && subdivisions <= 8,
                  "icosahedron subdivisions " << subdivisions);
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, t, 0},
                                    {1, t, 0},
                                    {-1, -t, 0},
                                    {1, -t, 0},
                                    {0, -1, t},
                                    {0, 1, t},
                                    {0, -1, -t},
                                    {0, 1, -t},
                                    {t, 0, -1},
                                    {t, 0, 1},
                                    {-t, 0, -1},
                                    {-t, 0, 1}};
  for (auto& p : v) p.normalize();
  std::vector<std::array<int, 3>> faces = {
      {0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> midpoint;
    auto mid = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      const int id = static_cast<int>(v.size()) - 1;
      midpoint.emplace(key, id);
      return id;
    };
    std::vector<std::array<int, 3>> next;
    next.reserve(faces.size() * 4);
    for (const auto& f : faces) {
      const int a = mid(f[0], f[1]);
      const int b = mid(f[1], f[2]);
      const int c = mid(f[2], f[0]);
      next.push_back({f[0], a, c});
      next.push_back({f[1], b, a});
      next.push_back({f[2], c, b});
      next.push_back({a, b, c});
    }
    faces = std::move(next);
  }
  return v;
}

int IcosahedronSubdivisionsForCount(int count) {
  long long n = 12;
  for (int k = 0; k <= 8; ++k) {
    if (n == count) return k;
    n = 10 * ((n - 2) / 10) * 4 + 2;
  }
  return -1;
}

namespace {

double Angle(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  // atan2 form: accurate for tiny and near-pi angles alike.
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// Indices of the three samples nearest to p (largest dot products).
std::array<int, 3> ThreeNearest(const std::vector<Eigen::Vector3d>& dirs,
                                const Eigen::Vector3d& p) {
  std::array<int, 3> best = {-1, -1, -1};
  std::array<double, 3> dot = {-2, -2, -2};
  for (int i = 0; i < static_cast<int>(dirs.size()); ++i) {
    const double d = dirs[i].dot(p);
    if (d > dot[2]) {
      int j = 2;
      while (j > 0 && d > dot[j - 1]) {
        dot[j] = dot[j - 1];
        best[j] = best[j - 1];
        --j;
      }
      dot[j] = d;
      best[j] = i;
    }
  }
  return best;
}

double NearestAngle(const std::vector<Eigen::Vector3d>& dirs, const Eigen::Vector3d& p) {
  double best = -2;
  for (const auto& d : dirs) best = std::max(best, d.dot(p));
  return std::acos(std::clamp(best, -1.0, 1.0));
}

}  // namespace

CoveringRadius ComputeCoveringRadius(const std::vector<Eigen::Vector3d>& directions, int probes) {
  THROW_CHECK_GE(directions.size(), 1u);
  THROW_CHECK_GE(probes, 1);
  CoveringRadius result;
  if (directions.size() < 3) {
    // Too few for a Voronoi vertex: fall back to the dense estimate alone.
    for (const auto& p : FibonacciDirections(probes)) {
      const double a = NearestAngle(directions, p);
      if (a > result.radians) {
        result.radians = a;
        result.farthest = p;
      }
    }
    result.dense_radians = result.radians;
    return result;
  }
  std::set<std::array<int, 3>> tried;
  for (const auto& p : FibonacciDirections(probes)) {
    const std::array<int, 3> nn = ThreeNearest(directions, p);
    const double dense = Angle(directions[nn[0]], p);
    if (dense > result.dense_radians) result.dense_radians = dense;
    std::array<int, 3> key = nn;
    std::sort(key.begin(), key.end());
    if (!tried.insert(key).second) continue;
    const Eigen::Vector3d& a = directions[nn[0]];
    const Eigen::Vector3d& b = directions[nn[1]];
    const Eigen::Vector3d& c = directions[nn[2]];
    Eigen::Vector3d centre = (b - a).cross(c - a);
    if (centre.norm() < 1e-14) continue;  // collinear on a great circle: no unique vertex
    centre.normalize();
    if (centre.dot(a) < 0) centre = -centre;  // the small circle's centre, on the samples' side
    const double r = Angle(centre, a);
    // A Voronoi vertex iff no sample lies strictly inside the circle through a, b, c.
    const double nearest = NearestAngle(directions, centre);
    if (nearest < r - 1e-9) continue;
    if (r > result.radians) {
      result.radians = r;
      result.farthest = centre;
    }
  }
  result.radians = std::max(result.radians, result.dense_radians);
  return result;
}

std::vector<double> RollAngles(int num_rolls) {
  THROW_CHECK_GE(num_rolls, 1);
  std::vector<double> out;
  for (int r = 0; r < num_rolls; ++r) out.push_back(2.0 * M_PI * r / num_rolls);
  return out;
}

}  // namespace handdb
