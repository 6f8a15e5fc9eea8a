// The pose fit's landmark residual (pose/fit.h): the rig's keypoint k, posed from its digit's
// angles, turned into the camera by the unit quaternion cam_from_hand, placed in the normalised
// frame by the scale and shift, minus the picture's landmark, over sigma. Only keypoint k's chain
// of bones is posed, from its digit's angles (the wrist's from none).
//
// LandmarkResidual is the residual as a template over the scalar, the definition. LandmarkCost is
// what the fit solves with: the same values, bit for bit, and the derivatives written out (the
// kinematic chain's by FitKinematics::KeypointOfDigitWithJacobian, the rotation's by hand), which
// pose/fit_kinematics_test.cc holds to Ceres' automatic derivatives of LandmarkResidual. Automatic
// derivatives carried 11 dual numbers through every product of the chain and were a sixth of a
// photo batch's CPU (docs/decisions/0030-landmark-derivatives-by-hand.md).
#pragma once

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <array>

#include "format/roll.h"
#include "format/view.h"
#include "pose/fit_kinematics.h"

namespace handdb::fit_internal {

class LandmarkResidual {
 public:
  LandmarkResidual(const FitKinematics* kinematics,
                   int keypoint,
                   const Vec3d& look_at,
                   const Point2f& landmark,
                   double inverse_sigma)
      : kinematics_(kinematics),
        keypoint_(keypoint),
        look_at_(look_at),
        landmark_{landmark.x, landmark.y},
        inverse_sigma_(inverse_sigma) {}

  // A digit's keypoint.
  template <typename T>
  bool operator()(
      const T* digit, const T* cam_from_hand, const T* scale, const T* shift, T* residuals) const {
    T point[3];
    kinematics_->KeypointOfDigit(digit, keypoint_, point);
    T in_cam[3];
    Project(point, cam_from_hand, scale, shift, residuals, in_cam);
    return true;
  }

  // The wrist, which no angle moves.
  template <typename T>
  bool operator()(const T* cam_from_hand, const T* scale, const T* shift, T* residuals) const {
    T point[3];
    kinematics_->KeypointOfDigit(static_cast<const T*>(nullptr), keypoint_, point);
    T in_cam[3];
    Project(point, cam_from_hand, scale, shift, residuals, in_cam);
    return true;
  }

  // From the keypoint in the hand frame to the residuals; `in_cam` receives the keypoint turned
  // into the camera, relative to the look-at point. `point` is changed.
  template <typename T>
  void Project(T* point,
               const T* cam_from_hand,
               const T* scale,
               const T* shift,
               T* residuals,
               T* in_cam) const {
    for (int r = 0; r < 3; ++r) point[r] -= T(look_at_[r]);
    ceres::UnitQuaternionRotatePoint(cam_from_hand, point, in_cam);
    for (int r = 0; r < 2; ++r) {
      residuals[r] = (scale[0] * in_cam[r] + shift[r] - T(landmark_[r])) * inverse_sigma_;
    }
  }

  const FitKinematics* kinematics() const { return kinematics_; }
  int keypoint() const { return keypoint_; }
  double inverse_sigma() const { return inverse_sigma_; }

 private:
  const FitKinematics* kinematics_;
  int keypoint_;
  Vec3d look_at_;
  std::array<double, 2> landmark_;
  double inverse_sigma_;
};

// LandmarkResidual with its Jacobians written out. Parameter blocks: the keypoint's digit's
// angles (FitKinematics::kDigitDofs; absent for the wrist), the rotation (4), the scale (1), the
// shift (2). Two residuals.
class LandmarkCost final : public ceres::CostFunction {
 public:
  static constexpr int kDigitDofs = FitKinematics::kDigitDofs;

  explicit LandmarkCost(const LandmarkResidual& residual) : residual_(residual) {
    set_num_residuals(2);
    if (residual_.keypoint() != 0) mutable_parameter_block_sizes()->push_back(kDigitDofs);
    mutable_parameter_block_sizes()->push_back(4);
    mutable_parameter_block_sizes()->push_back(1);
    mutable_parameter_block_sizes()->push_back(2);
  }

  bool Evaluate(double const* const* parameters,
                double* residuals,
                double** jacobians) const override {
    const bool wrist = residual_.keypoint() == 0;
    const int first = wrist ? 0 : 1;
    const double* digit = wrist ? nullptr : parameters[0];
    const double* q = parameters[first];
    const double* scale = parameters[first + 1];
    const double* shift = parameters[first + 2];
    double point[3];
    double point_jacobian[3][kDigitDofs];
    residual_.kinematics()->KeypointOfDigitWithJacobian(
        digit, residual_.keypoint(), point, point_jacobian);
    double in_cam[3];
    residual_.Project(point, q, scale, shift, residuals, in_cam);  // point -= look_at
    if (jacobians == nullptr) return true;

    const double k = scale[0] * residual_.inverse_sigma();
    // Ceres' rotation is linear in the point: its matrix's columns are the turned unit vectors.
    double turn[3][3];
    for (int c = 0; c < 3; ++c) {
      const double unit[3] = {c == 0 ? 1.0 : 0.0, c == 1 ? 1.0 : 0.0, c == 2 ? 1.0 : 0.0};
      double column[3];
      ceres::UnitQuaternionRotatePoint(q, unit, column);
      for (int r = 0; r < 3; ++r) turn[r][c] = column[r];
    }
    if (!wrist && jacobians[0] != nullptr) {
      for (int r = 0; r < 2; ++r) {
        for (int i = 0; i < kDigitDofs; ++i) {
          jacobians[0][r * kDigitDofs + i] =
              k * (turn[r][0] * point_jacobian[0][i] + turn[r][1] * point_jacobian[1][i] +
                   turn[r][2] * point_jacobian[2][i]);
        }
      }
    }
    if (jacobians[first] != nullptr) {
      // Ceres turns p by p + 2 w (u x p) + 2 u x (u x p), q = (w, u), as written (not normalised).
      double rotation_jacobian[3][4];
      RotationJacobian(q, point, rotation_jacobian);
      for (int r = 0; r < 2; ++r) {
        for (int i = 0; i < 4; ++i) jacobians[first][r * 4 + i] = k * rotation_jacobian[r][i];
      }
    }
    if (jacobians[first + 1] != nullptr) {
      for (int r = 0; r < 2; ++r) jacobians[first + 1][r] = in_cam[r] * residual_.inverse_sigma();
    }
    if (jacobians[first + 2] != nullptr) {
      jacobians[first + 2][0] = residual_.inverse_sigma();
      jacobians[first + 2][1] = 0;
      jacobians[first + 2][2] = 0;
      jacobians[first + 2][3] = residual_.inverse_sigma();
    }
    return true;
  }

 private:
  // d/dq of p + 2 w (u x p) + 2 u x (u x p) for q = (w, u): column 0 is 2 (u x p); column 1 + i is
  // 2 w (e_i x p) + 2 (e_i x (u x p) + u x (e_i x p)).
  static void RotationJacobian(const double* q, const double* p, double (&out)[3][4]) {
    const double* u = q + 1;
    double u_p[3];
    ceres::CrossProduct(u, p, u_p);
    for (int r = 0; r < 3; ++r) out[r][0] = 2 * u_p[r];
    for (int i = 0; i < 3; ++i) {
      const double e[3] = {i == 0 ? 1.0 : 0.0, i == 1 ? 1.0 : 0.0, i == 2 ? 1.0 : 0.0};
      double e_p[3], e_u_p[3], u_e_p[3];
      ceres::CrossProduct(e, p, e_p);
      ceres::CrossProduct(e, u_p, e_u_p);
      ceres::CrossProduct(u, e_p, u_e_p);
      for (int r = 0; r < 3; ++r) out[r][1 + i] = 2 * (q[0] * e_p[r] + e_u_p[r] + u_e_p[r]);
    }
  }

  LandmarkResidual residual_;
};

}  // namespace handdb::fit_internal
