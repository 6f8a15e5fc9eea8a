// The data every module shares: ids, the fixed-point point type, the pose label of a canonical
// view, and the virtual (view, roll) expansion. Conventions: docs/conventions.md.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>

namespace handdb {

using view_id_t = uint32_t;    // canonical view index inside a database (manifest order)
using shape_id_t = uint32_t;   // index into the plan's shape table
using dir_id_t = uint32_t;     // index into the plan's view-direction table
using render_id_t = uint32_t;  // index of the render item in the plan (shape-major)
using roll_id_t = uint32_t;    // 0..R-1, angle = 2*pi*roll_id/R
constexpr view_id_t kInvalidViewId = std::numeric_limits<view_id_t>::max();
constexpr shape_id_t kInvalidShapeId = std::numeric_limits<shape_id_t>::max();
constexpr dir_id_t kInvalidDirId = std::numeric_limits<dir_id_t>::max();
constexpr render_id_t kInvalidRenderId = std::numeric_limits<render_id_t>::max();

constexpr int kNumJointAngles = 20;
constexpr int kNumKeypoints = 21;
constexpr int kNumLinks = 16;  // link ids 1..16, 0 = background
// Joint angles in the hand model's DOF order (docs/conventions.md), radians.
using JointVector = std::array<double, kNumJointAngles>;

// Per-DOF [min, max] of a hand model.
struct JointLimits {
  JointVector min{};
  JointVector max{};
  bool Contains(const JointVector& joints, double tolerance = 1e-9) const {
    for (int i = 0; i < kNumJointAngles; ++i) {
      if (!(joints[i] >= min[i] - tolerance && joints[i] <= max[i] + tolerance)) return false;
    }
    return true;
  }
  // Clamps in place; returns true when any joint changed.
  bool Clamp(JointVector* joints) const {
    bool changed = false;
    for (int i = 0; i < kNumJointAngles; ++i) {
      const double c = std::clamp((*joints)[i], min[i], max[i]);
      if (c != (*joints)[i]) {
        (*joints)[i] = c;
        changed = true;
      }
    }
    return changed;
  }
};

constexpr float kNormalisedDiameter = 192.0f;  // px, largest distance between two contour points

// Edge points are stored as fixed point in the canonical normalised frame: origin at the
// normalisation centre, x right, y down, units of 1/kPointScale px. int16 covers +-2048 px.
constexpr float kPointScale = 16.0f;
struct PointQ {
  int16_t x;
  int16_t y;
};
static_assert(sizeof(PointQ) == 4);

inline float PointQToPx(int16_t v) { return static_cast<float>(v) / kPointScale; }

// Pose label of one canonical (roll 0) view, in the normalised frame. Plain data, little-endian
// on disk as laid out in docs/format.md.
struct ViewLabel {
  render_id_t render_id = kInvalidRenderId;
  shape_id_t shape_id = kInvalidShapeId;
  dir_id_t dir_id = kInvalidDirId;
  uint32_t flags = 0;                                 // reserved, 0
  std::array<float, kNumJointAngles> joint_angles{};  // radians, hand-model DOF order
  std::array<float, 3> view_direction{};              // unit vector hand->camera, hand frame
  float view_theta = 0;                               // acos(dir.z), radians
  float view_phi = 0;                                 // atan2(dir.y, dir.x), radians
  float camera_roll = 0;                              // radians, of the rendered image (normally 0)
  // 21 keypoints: x, y in normalised px (same frame as the points), z depth in the same px
  // units, measured away from the camera, relative to the camera's look-at plane.
  std::array<std::array<float, 3>, kNumKeypoints> keypoints{};
  float source_diameter_px = 0;             // contour diameter in the rendered image
  float scale = 0;                          // normalised px per rendered px
  std::array<float, 2> source_centre_px{};  // normalisation centre in the rendered image
};

// Roll is virtual (docs/conversion.md): the view (v, r) is canonical view v rotated in the image
// plane by angle a = 2*pi*r/R:  x' = cos(a) x - sin(a) y,  y' = sin(a) x + cos(a) y
// (x right, y down: positive a turns +x towards +y, i.e. clockwise on screen). Its pose label
// is the canonical one with camera_roll += a and keypoints (x, y) rotated the same way.
inline float RollAngle(roll_id_t roll, uint32_t num_rolls) {
  return static_cast<float>(2.0 * M_PI * static_cast<double>(roll) /
                            static_cast<double>(num_rolls));
}

}  // namespace handdb
