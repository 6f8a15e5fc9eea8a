#include "edges/synthetic_hand.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace handdb {
namespace {

struct Vec {
  double x;
  double y;
};

struct Capsule {
  Vec a;
  Vec b;
  double radius;
  uint8_t label;
  float depth;
};

double SegmentDistance2(const Vec& p, const Vec& a, const Vec& b) {
  const double dx = b.x - a.x;
  const double dy = b.y - a.y;
  const double len2 = dx * dx + dy * dy;
  double t = len2 > 0 ? ((p.x - a.x) * dx + (p.y - a.y) * dy) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  const double ex = p.x - (a.x + t * dx);
  const double ey = p.y - (a.y + t * dy);
  return ex * ex + ey * ey;
}

}  // namespace

SyntheticHand RenderSyntheticHand(const SyntheticHandParams& params) {
  // Hand units: x right, y down, origin at the palm centre, fingers pointing up (-y).
  std::vector<Capsule> capsules;
  std::array<Vec, kNumKeypoints> keypoints{};
  const Vec wrist{0, 48};
  keypoints[0] = wrist;
  capsules.push_back({{-6, 22}, {6, -8}, 30, 1, 1.0f});  // palm (slightly skewed: unique diameter)

  struct Finger {
    Vec base;
    double direction;  // radians from "up"
    std::array<double, 3> lengths;
    double radius;
  };
  const std::array<Finger, 5> fingers = {{
      {{-30, 20}, -1.0, {{22, 18, 15}}, 7.5},    // thumb
      {{-22, -30}, -0.12, {{26, 17, 14}}, 6.5},  // index
      {{-7, -34}, -0.03, {{29, 19, 15}}, 6.5},   // middle
      {{8, -32}, 0.07, {{27, 18, 14}}, 6.0},     // ring
      {{22, -26}, 0.2, {{21, 14, 12}}, 5.5},     // pinky
  }};
  for (int f = 0; f < 5; ++f) {
    const Finger& fg = fingers[f];
    const uint8_t first_label = static_cast<uint8_t>(f == 0 ? 2 : 5 + 3 * (f - 1));
    Vec p = fg.base;
    keypoints[1 + 4 * f] = p;
    double dir = fg.direction;
    const bool folded = params.folded[f];
    for (int k = 0; k < 3; ++k) {
      // Folded: the finger turns back down over the palm, nearer to the camera.
      if (folded && k == 0) dir += M_PI * 0.92;
      if (k > 0) dir += params.bend[f];
      const Vec q{p.x + fg.lengths[k] * std::sin(dir), p.y - fg.lengths[k] * std::cos(dir)};
      const float depth = folded ? 0.97f : 1.0f;
      capsules.push_back({p, q, fg.radius, static_cast<uint8_t>(first_label + k), depth});
      keypoints[2 + 4 * f + k] = q;
      p = q;
    }
  }

  SyntheticHand out;
  LabelImage& image = out.image;
  image.width = params.width;
  image.height = params.height;
  const size_t n = static_cast<size_t>(image.width) * image.height;
  image.labels.assign(n, 0);
  image.depth.assign(n, params.background_depth);
  const double c = std::cos(params.angle);
  const double s = std::sin(params.angle);
  for (int row = 0; row < image.height; ++row) {
    for (int col = 0; col < image.width; ++col) {
      // Pixel centre -> hand units (inverse of the forward map below).
      const double dx = (col + 0.5 - params.centre_x) / params.scale;
      const double dy = (row + 0.5 - params.centre_y) / params.scale;
      const Vec q{c * dx + s * dy, -s * dx + c * dy};
      const size_t i = static_cast<size_t>(row) * image.width + col;
      for (const Capsule& cap : capsules) {
        if (cap.depth < image.depth[i] &&
            SegmentDistance2(q, cap.a, cap.b) <= cap.radius * cap.radius) {
          image.depth[i] = cap.depth;
          image.labels[i] = cap.label;
        }
      }
    }
  }
  for (int k = 0; k < kNumKeypoints; ++k) {
    const Vec& q = keypoints[k];
    out.keypoints_px[k] = {params.centre_x + params.scale * (c * q.x - s * q.y),
                           params.centre_y + params.scale * (s * q.x + c * q.y),
                           0.0};
  }
  return out;
}

}  // namespace handdb
