// Deterministic synthetic edge sets and in-memory databases for the query tests and
// bench/query_bench.cc: "hand-like" point sets (an outline ellipse plus a few finger-like strokes),
// about kNormalisedDiameter across, in the canonical frame.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "format/roll.h"
#include "format/view.h"
#include "query/database.h"

namespace handdb::testing {

// About n points: an ellipse outline (60% of the points) and 3-5 straight strokes radiating from
// near the centre, with a random orientation.
inline std::vector<PointQ> SyntheticEdgeSet(uint32_t seed, size_t n) {
  std::mt19937 rng(seed * 7919u + 17u);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double a = 96.0;
  const double b = 40.0 + 50.0 * u(rng);
  const double phi = 2 * M_PI * u(rng);
  const double c = std::cos(phi);
  const double s = std::sin(phi);
  std::vector<PointQ> pts;
  auto add = [&](double x, double y) {
    const double rx = c * x - s * y;
    const double ry = s * x + c * y;
    pts.push_back({static_cast<int16_t>(std::lround(rx * kPointScale)),
                   static_cast<int16_t>(std::lround(ry * kPointScale))});
  };
  const size_t n_outline = n * 6 / 10;
  for (size_t k = 0; k < n_outline; ++k) {
    const double t =
        2 * M_PI * (static_cast<double>(k) + 0.3 * u(rng)) / static_cast<double>(n_outline);
    add(a * std::cos(t), b * std::sin(t));
  }
  const int strokes = 3 + static_cast<int>(u(rng) * 3);
  const size_t per_stroke = (n - n_outline) / strokes;
  for (int k = 0; k < strokes; ++k) {
    const double t = 2 * M_PI * u(rng);
    const double len = 0.4 + 0.5 * u(rng);
    const double x0 = 10 * (u(rng) - 0.5);
    const double y0 = 10 * (u(rng) - 0.5);
    for (size_t j = 0; j < per_stroke; ++j) {
      const double f = len * static_cast<double>(j) / static_cast<double>(per_stroke);
      add(x0 + f * a * std::cos(t), y0 + f * b * std::sin(t));
    }
  }
  return pts;
}

inline ViewLabel SyntheticViewLabel(uint32_t v, uint32_t views_per_shape) {
  std::mt19937 rng(v + 12345u);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  ViewLabel l;
  l.render_id = v;
  l.shape_id = v / views_per_shape;
  l.dir_id = v % views_per_shape;
  for (auto& j : l.joint_angles) j = 1.2f * u(rng);
  const float theta = std::acos(1 - 2 * u(rng));
  const float phi = static_cast<float>(M_PI) * (2 * u(rng) - 1);
  l.view_direction = {
      std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
  l.view_theta = theta;
  l.view_phi = phi;
  for (auto& kp : l.keypoints) kp = {180 * u(rng) - 90, 180 * u(rng) - 90, 100 * u(rng) - 50};
  l.source_diameter_px = 150;
  l.scale = kNormalisedDiameter / 150;
  l.source_centre_px = {128, 128};
  return l;
}

inline Database SyntheticDatabase(uint32_t num_views,
                                  size_t points_per_view,
                                  uint32_t num_rolls,
                                  uint32_t views_per_shape = 86) {
  std::vector<ViewLabel> labels;
  std::vector<std::vector<PointQ>> points;
  std::vector<std::string> names;
  for (uint32_t v = 0; v < num_views; ++v) {
    labels.push_back(SyntheticViewLabel(v, views_per_shape));
    points.push_back(SyntheticEdgeSet(v, points_per_view));
  }
  for (uint32_t s = 0; s <= num_views / views_per_shape; ++s)
    names.push_back("shape" + std::to_string(s));
  return Database::FromMemory(std::move(labels), std::move(points), num_rolls, std::move(names));
}

// A hand-like edge set for (shape, direction) of a shapes x directions grid, normalised like the
// database (diameter of the point set 192 px, centred on the diameter's midpoint): a palm
// outline and five fingers (two sides and a tip each) whose lengths depend on the shape's "curl"
// and whose projection depends on the direction (foreshortening and in-plane turn), so
// neighbouring directions of one shape look alike, as in a rendered database. About n points.
inline std::vector<PointQ> SyntheticHandEdges(uint32_t shape,
                                              uint32_t direction,
                                              uint32_t num_directions,
                                              size_t n) {
  std::mt19937 shape_rng(shape * 131u + 7u);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  struct Seg {
    double x0, y0, x1, y1;
  };
  std::vector<Seg> segs;
  // Palm: an octagon-ish outline.
  const int palm_sides = 10;
  const double pw = 40, ph = 46;
  for (int k = 0; k < palm_sides; ++k) {
    const double t0 = 2 * M_PI * k / palm_sides, t1 = 2 * M_PI * (k + 1) / palm_sides;
    segs.push_back({pw * std::cos(t0), ph * std::sin(t0), pw * std::cos(t1), ph * std::sin(t1)});
  }
  // Fingers: thumb on the side, four fanned on top (y up = negative y).
  const double base_angle[5] = {-2.5, -1.95, -1.66, -1.40, -1.15};
  const double base_len[5] = {55, 70, 78, 72, 58};
  for (int f = 0; f < 5; ++f) {
    const double curl = u(shape_rng);
    const double spread = 0.25 * (u(shape_rng) - 0.5);
    const double len = base_len[f] * (1.0 - 0.75 * curl);
    const double a = base_angle[f] + spread;
    const double bx = 0.9 * pw * std::cos(a), by = 0.9 * ph * std::sin(a);
    const double dx = std::cos(a), dy = std::sin(a);
    const double w = f == 0 ? 9 : 7.5;
    const double nx = -dy * w, ny = dx * w;
    const double tx = bx + dx * len, ty = by + dy * len;
    segs.push_back({bx + nx, by + ny, tx + nx, ty + ny});
    segs.push_back({bx - nx, by - ny, tx - nx, ty - ny});
    segs.push_back({tx + nx, ty + ny, tx - nx, ty - ny});
    if (curl > 0.4) segs.push_back({bx + nx, by + ny, bx - nx, by - ny});  // a crease
  }
  // Direction: Fibonacci sphere point -> foreshortening along x and an in-plane turn.
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  const double z = 1.0 - 2.0 * (direction + 0.5) / num_directions;
  const double phi = golden * direction;
  const double squash = 0.35 + 0.65 * std::fabs(z);
  const double c = std::cos(phi), s = std::sin(phi);
  auto project = [&](double x, double y) {
    x *= squash;
    return std::pair<double, double>(c * x - s * y, s * x + c * y);
  };
  double total = 0;
  for (const Seg& g : segs) total += std::hypot(g.x1 - g.x0, g.y1 - g.y0);
  std::vector<std::pair<double, double>> pts;
  for (const Seg& g : segs) {
    const double len = std::hypot(g.x1 - g.x0, g.y1 - g.y0);
    const int m = std::max(1, static_cast<int>(std::lround(len / total * static_cast<double>(n))));
    for (int j = 0; j < m; ++j) {
      const double t = (j + 0.5) / m;
      pts.push_back(project(g.x0 + t * (g.x1 - g.x0), g.y0 + t * (g.y1 - g.y0)));
    }
  }
  // Normalise: diameter 192, centre at its midpoint.
  double best = -1;
  size_t ia = 0, ib = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    for (size_t j = i + 1; j < pts.size(); ++j) {
      const double d = std::hypot(pts[i].first - pts[j].first, pts[i].second - pts[j].second);
      if (d > best) {
        best = d;
        ia = i;
        ib = j;
      }
    }
  }
  const double scale = kNormalisedDiameter / best;
  const double cx = 0.5 * (pts[ia].first + pts[ib].first);
  const double cy = 0.5 * (pts[ia].second + pts[ib].second);
  std::vector<PointQ> out;
  out.reserve(pts.size());
  for (const auto& [x, y] : pts) {
    out.push_back({static_cast<int16_t>(std::lround((x - cx) * scale * kPointScale)),
                   static_cast<int16_t>(std::lround((y - cy) * scale * kPointScale))});
  }
  return out;
}

// The points of virtual view (v, r) in px: canonical points rolled (format/roll.h).
inline std::vector<Point2f> RolledView(const Database& db, view_id_t v, roll_id_t r) {
  std::vector<Point2f> out;
  RollPoints(db.points(v), RollAngle(r, db.num_rolls()), &out);
  return out;
}

}  // namespace handdb::testing
