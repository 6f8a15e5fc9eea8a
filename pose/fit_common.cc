// The parts of pose/fit.h that need no solver: the options' check, a fit's start from a stored
// view and the view of a rotation. Linked into handdb_pose, so checking options or preparing a
// start never loads the fit's solver (pose/fit_plugin.h), and into the solver's plugin, which
// calls them too.
#include <cmath>

#include "pose/fit.h"

namespace handdb {

bool PoseFitOptions::Check() const {
  CHECK_OPTION(std::isfinite(landmark_sigma_px) && landmark_sigma_px > 0);
  CHECK_OPTION(std::isfinite(landmark_loss_scale) && landmark_loss_scale > 0);
  CHECK_OPTION(std::isfinite(joint_prior_sigma) && joint_prior_sigma > 0);
  CHECK_OPTION(std::isfinite(rotation_prior_sigma) && rotation_prior_sigma > 0);
  CHECK_OPTION(std::isfinite(silhouette_sigma_px) && silhouette_sigma_px > 0);
  CHECK_OPTION(std::isfinite(silhouette_loss_scale) && silhouette_loss_scale > 0);
  CHECK_OPTION(std::isfinite(inside_weight) && inside_weight >= 0);
  CHECK_OPTION(std::isfinite(edge_weight) && edge_weight >= 0);
  CHECK_OPTION(std::isfinite(cover_weight) && cover_weight >= 0);
  CHECK_OPTION(std::isfinite(depth_sigma) && depth_sigma > 0);
  CHECK_OPTION(std::isfinite(depth_loss_scale) && depth_loss_scale > 0);
  CHECK_OPTION(std::isfinite(depth_weight) && depth_weight >= 0);
  CHECK_OPTION_GE(max_iterations, 1);
  CHECK_OPTION(function_tolerance > 0 && function_tolerance < 1);
  CHECK_OPTION_GE(num_threads, 1);
  return true;
}

Status ViewOfCamFromHand(const HandRig& rig,
                         const Mat3d& cam_from_hand,
                         Vec3d* view_direction,
                         double* roll) {
  // The camera's z axis points away from the camera; the view direction points towards it.
  const Vec3d direction{-cam_from_hand[2][0], -cam_from_hand[2][1], -cam_from_hand[2][2]};
  auto unrolled = CamFromHand(rig, direction, 0.0);
  if (!unrolled.ok()) return unrolled.status();
  // Roll a turns the unrolled right axis into row 0 = cos a right - sin a down and row 1 =
  // sin a right + cos a down.
  const Vec3d& right = (*unrolled)[0];
  double c = 0, s = 0;
  for (int i = 0; i < 3; ++i) {
    c += cam_from_hand[0][i] * right[i];
    s += cam_from_hand[1][i] * right[i];
  }
  *view_direction = direction;
  *roll = std::atan2(s, c);
  return Status::Ok();
}

Result<PoseFitStart> PoseFitStartFromLabel(const HandRig& rig,
                                           const ViewLabel& label,
                                           const RenderSettings& render,
                                           double virtual_roll) {
  auto keypoints = ViewKeypointsNormalised(rig, label, render, virtual_roll);
  if (!keypoints.ok()) return keypoints.status();
  PoseFitStart start;
  for (int i = 0; i < kNumJointAngles; ++i) start.joints[i] = label.joint_angles[i];
  start.view_direction = {
      label.view_direction[0], label.view_direction[1], label.view_direction[2]};
  start.roll = label.camera_roll + virtual_roll;
  for (int k = 0; k < kNumKeypoints; ++k) {
    start.keypoints_normalised[k] = {static_cast<float>((*keypoints)[k][0]),
                                     static_cast<float>((*keypoints)[k][1])};
  }
  return start;
}

}  // namespace handdb
