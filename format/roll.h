// Virtual roll (docs/conventions.md): rotate canonical points / keypoints in the image plane.
#pragma once

#include <cmath>
#include <span>
#include <vector>

#include "format/view.h"

namespace handdb {

struct Point2f {
  float x;
  float y;
};

// Rotates fixed-point canonical points by roll angle `angle` (radians) into float px.
inline void RollPoints(std::span<const PointQ> in, float angle, std::vector<Point2f>* out) {
  const float c = std::cos(angle) / kPointScale;
  const float s = std::sin(angle) / kPointScale;
  out->resize(in.size());
  for (size_t i = 0; i < in.size(); ++i) {
    const float x = in[i].x;
    const float y = in[i].y;
    (*out)[i] = {c * x - s * y, s * x + c * y};
  }
}

// The label of virtual view (v, roll): camera_roll += angle, keypoints (x, y) rotated.
inline ViewLabel RollLabel(const ViewLabel& label, float angle) {
  ViewLabel out = label;
  const float c = std::cos(angle);
  const float s = std::sin(angle);
  for (auto& kp : out.keypoints) {
    const float x = kp[0];
    const float y = kp[1];
    kp[0] = c * x - s * y;
    kp[1] = s * x + c * y;
  }
  out.camera_roll = std::remainder(label.camera_roll + angle, static_cast<float>(2.0 * M_PI));
  return out;
}

}  // namespace handdb
