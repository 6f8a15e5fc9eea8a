// The orthographic camera of the renders (blender_scripts/handdb_blender/camera.py,
// docs/conventions.md "Frames and angles"): the camera rotation for a view direction and roll,
// the projection to rendered pixels, and a stored view's 21 keypoints recomputed from its label
// (joint angles, view direction, roll) in rendered px and in the normalised frame the shards
// store. With HandRig this is the query side's model of how every database view was made.
#pragma once

#include <array>
#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"
#include "format/view.h"
#include "generator/hand/kinematics.h"

namespace handdb {

// Looking (almost) along the fingers, the forward axis no longer gives a stable image up: above
// this |view_direction . forward_axis| the image up is -palm_normal instead.
constexpr double kCameraPoleThreshold = 0.99;

// What a render's projection depends on besides the view: the plan's `render` block, recorded by
// the converter in every database's `generation` metadata.
struct RenderSettings {
  int resolution = 0;      // px, square image
  double ortho_scale = 0;  // hand-frame units across the image
  bool Check() const;
  // From `generation.resolution` / `generation.ortho_scale` of a manifest's or shard's metadata;
  // kSchemaViolation (starting with `what`) when either is missing or out of range.
  static Result<RenderSettings> FromMetadata(const nlohmann::json& metadata,
                                             const std::string& what);
};

// Rows: the camera's x (right), y (down), z (away from the camera) axes in the hand frame, so
// point_in_cam = cam_from_hand * (point_in_hand - look_at). Roll 0: image up is forward_axis
// projected onto the image plane (-palm_normal near the pole); roll a then turns the image
// content by a (x' = cos a x - sin a y, y' = sin a x + cos a y). kInvalidArgument for a zero or
// non-finite direction or axis, or a palm normal along the view direction at the pole.
Result<Mat3d> CamFromHandRotation(const Vec3d& view_direction,
                                  const Vec3d& forward_axis,
                                  const Vec3d& palm_normal,
                                  double roll);
// The same with the rig's forward axis and palm normal.
Result<Mat3d> CamFromHand(const HandRig& rig, const Vec3d& view_direction, double roll);

// A hand-frame point -> (u, v, depth_px): pixel centres at integer + 0.5, the look-at point at
// (resolution / 2, resolution / 2), depth in px away from the camera from the look-at plane.
Vec3d ProjectToRenderPx(const Vec3d& point_in_hand,
                        const Vec3d& look_at,
                        const Mat3d& cam_from_hand,
                        const RenderSettings& params);

using ViewKeypoints = std::array<Vec3d, kNumKeypoints>;

// The keypoints of a stored (canonical) view's label as its render made them: the rig posed with
// label.joint_angles, seen from label.view_direction with label.camera_roll, in rendered px.
Result<ViewKeypoints> ViewKeypointsPx(const HandRig& rig,
                                      const ViewLabel& label,
                                      const RenderSettings& params);
// The same in the normalised frame, with the view's stored normalisation (label.scale,
// label.source_centre_px) applied as the converter applies it; `virtual_roll` (radians) then
// turns them like the virtual view (v, r) of format/roll.h (RollAngle(r, R)).
Result<ViewKeypoints> ViewKeypointsNormalised(const HandRig& rig,
                                              const ViewLabel& label,
                                              const RenderSettings& params,
                                              double virtual_roll = 0);

}  // namespace handdb
