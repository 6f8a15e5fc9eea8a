#include "generator/hand/camera.h"

#include <cmath>
#include <sstream>

#include "edges/normalise.h"

namespace handdb {
namespace {

double Dot3(const Vec3d& a, const Vec3d& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

Vec3d Cross3(const Vec3d& a, const Vec3d& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

Result<Vec3d> UnitVector(const Vec3d& v, const char* what) {
  const double n = std::sqrt(Dot3(v, v));
  if (!std::isfinite(n) || n < 1e-12) {
    std::ostringstream os;
    os << what << " must be a non-zero finite 3-vector, got [" << v[0] << ", " << v[1] << ", "
       << v[2] << "]";
    return Status(StatusCode::kInvalidArgument, os.str());
  }
  return Vec3d{v[0] / n, v[1] / n, v[2] / n};
}

}  // namespace

bool RenderSettings::Check() const {
  return resolution > 0 && std::isfinite(ortho_scale) && ortho_scale > 0;
}

Result<RenderSettings> RenderSettings::FromMetadata(const nlohmann::json& metadata,
                                                    const std::string& what) {
  const auto bad = [&](const std::string& problem) {
    return Status(StatusCode::kSchemaViolation, what + ": generation: " + problem);
  };
  if (!metadata.is_object() || !metadata.contains("generation") ||
      !metadata["generation"].is_object()) {
    return bad("missing (the render resolution and ortho_scale are not recorded)");
  }
  const nlohmann::json& gen = metadata["generation"];
  RenderSettings params;
  if (!gen.contains("resolution") || !gen["resolution"].is_number_integer()) {
    return bad("resolution missing or not an integer");
  }
  if (!gen.contains("ortho_scale") || !gen["ortho_scale"].is_number()) {
    return bad("ortho_scale missing or not a number");
  }
  params.resolution = gen["resolution"].get<int>();
  params.ortho_scale = gen["ortho_scale"].get<double>();
  if (!params.Check()) {
    std::ostringstream os;
    os << "resolution " << params.resolution << " and ortho_scale " << params.ortho_scale
       << " must both be > 0";
    return bad(os.str());
  }
  return params;
}

Result<Mat3d> CamFromHandRotation(const Vec3d& view_direction,
                                  const Vec3d& forward_axis,
                                  const Vec3d& palm_normal,
                                  double roll) {
  auto d = UnitVector(view_direction, "view direction");
  if (!d.ok()) return d.status();
  auto fwd = UnitVector(forward_axis, "forward_axis");
  if (!fwd.ok()) return fwd.status();
  Vec3d ref = *fwd;
  if (std::abs(Dot3(*d, *fwd)) > kCameraPoleThreshold) {
    auto palm = UnitVector(palm_normal, "palm_normal");
    if (!palm.ok()) return palm.status();
    ref = {-(*palm)[0], -(*palm)[1], -(*palm)[2]};
  }
  const double along = Dot3(ref, *d);
  Vec3d up{ref[0] - along * (*d)[0], ref[1] - along * (*d)[1], ref[2] - along * (*d)[2]};
  const double n = std::sqrt(Dot3(up, up));
  if (n < 1e-9) {
    return Status(StatusCode::kInvalidArgument,
                  "palm_normal is parallel to the view direction at the pole");
  }
  const Vec3d forward{-(*d)[0], -(*d)[1], -(*d)[2]};  // optical axis, away from the camera
  const Vec3d down{-up[0] / n, -up[1] / n, -up[2] / n};
  const Vec3d right = Cross3(down, forward);  // OpenCV: x = y cross z
  const double c = std::cos(roll);
  const double s = std::sin(roll);
  Mat3d r;
  for (int i = 0; i < 3; ++i) {
    r[0][i] = c * right[i] - s * down[i];
    r[1][i] = s * right[i] + c * down[i];
    r[2][i] = forward[i];
  }
  return r;
}

Result<Mat3d> CamFromHand(const HandRig& rig, const Vec3d& view_direction, double roll) {
  return CamFromHandRotation(view_direction, rig.forward_axis(), rig.palm_normal(), roll);
}

Vec3d ProjectToRenderPx(const Vec3d& point_in_hand,
                        const Vec3d& look_at,
                        const Mat3d& cam_from_hand,
                        const RenderSettings& params) {
  THROW_CHECK(params.Check());
  const Vec3d p{
      point_in_hand[0] - look_at[0], point_in_hand[1] - look_at[1], point_in_hand[2] - look_at[2]};
  const double px_per_unit = params.resolution / params.ortho_scale;
  const double half = params.resolution / 2.0;
  return {half + Dot3(cam_from_hand[0], p) * px_per_unit,
          half + Dot3(cam_from_hand[1], p) * px_per_unit,
          Dot3(cam_from_hand[2], p) * px_per_unit};
}

Result<ViewKeypoints> ViewKeypointsPx(const HandRig& rig,
                                      const ViewLabel& label,
                                      const RenderSettings& params) {
  if (!params.Check()) {
    return Status(StatusCode::kInvalidArgument, "render resolution and ortho_scale must be > 0");
  }
  JointVector joints;
  for (int i = 0; i < kNumJointAngles; ++i) joints[i] = label.joint_angles[i];
  const Vec3d direction{label.view_direction[0], label.view_direction[1], label.view_direction[2]};
  auto cam_from_hand = CamFromHand(rig, direction, label.camera_roll);
  if (!cam_from_hand.ok()) return cam_from_hand.status();
  const HandKeypoints3d points = rig.Keypoints3d(joints);
  ViewKeypoints out;
  for (int k = 0; k < kNumKeypoints; ++k) {
    out[k] = ProjectToRenderPx(points[k], rig.look_at(), *cam_from_hand, params);
  }
  return out;
}

Result<ViewKeypoints> ViewKeypointsNormalised(const HandRig& rig,
                                              const ViewLabel& label,
                                              const RenderSettings& params,
                                              double virtual_roll) {
  auto px = ViewKeypointsPx(rig, label, params);
  if (!px.ok()) return px.status();
  if (!(label.scale > 0)) {
    return Status(
        StatusCode::kInvalidArgument,
        "the view's label records no normalisation (scale " + std::to_string(label.scale) + ")");
  }
  Normalisation norm;
  norm.centre_x = label.source_centre_px[0];
  norm.centre_y = label.source_centre_px[1];
  norm.scale = label.scale;
  const double c = std::cos(virtual_roll);
  const double s = std::sin(virtual_roll);
  ViewKeypoints out;
  for (int k = 0; k < kNumKeypoints; ++k) {
    const std::array<float, 3> n = NormaliseKeypoint((*px)[k], norm);
    out[k] = {c * n[0] - s * n[1], s * n[0] + c * n[1], n[2]};
  }
  return out;
}

}  // namespace handdb
