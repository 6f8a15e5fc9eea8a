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

// The points of virtual view (v, r) in px: canonical points rolled (format/roll.h).
inline std::vector<Point2f> RolledView(const Database& db, view_id_t v, roll_id_t r) {
  std::vector<Point2f> out;
  RollPoints(db.points(v), RollAngle(r, db.num_rolls()), &out);
  return out;
}

}  // namespace handdb::testing
