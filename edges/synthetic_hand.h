// A 2D synthetic "hand" rasterised into a link-label image with depth: capsules for the palm and
// the 15 finger links, with exact keypoints. Tests and benchmarks use it where a known answer is
// needed (rotating the input by an exact angle, folding a finger over the palm) or where Blender
// renders are not available. Not a substitute for real renders in anything that is measured
// about real hands.
#pragma once

#include <array>

#include "edges/edges.h"
#include "format/view.h"

namespace handdb {

struct SyntheticHandParams {
  int width = 256;
  int height = 256;
  double centre_x = 128;  // image position of the hand origin (the palm centre)
  double centre_y = 128;
  double angle = 0;    // in-plane rotation, radians, docs/conventions.md roll sense
  double scale = 1.0;  // rendered px per hand unit (the hand is ~175 units long)
  // Per finger (thumb, index, middle, ring, pinky): sideways bend of each joint (radians) and
  // whether the finger is folded back over the palm (nearer to the camera: an occlusion).
  std::array<double, 5> bend{};
  std::array<bool, 5> folded{};
  float background_depth = 1e10f;
};

struct SyntheticHand {
  LabelImage image;
  // 21 keypoints (docs/conventions.md order): u, v in rendered px, depth in px (0 here).
  std::array<std::array<double, 3>, kNumKeypoints> keypoints_px{};
};

SyntheticHand RenderSyntheticHand(const SyntheticHandParams& params);

}  // namespace handdb
