// The hand rig's forward kinematics templated on the scalar, so a solver can differentiate the 21
// keypoints with respect to the joint angles automatically (a Ceres Jet is a scalar here). It is
// the computation of HandRig::Keypoints3d (generator/hand/kinematics.cc) rewritten per keypoint:
// a keypoint only depends on the bones from its root down to its own bone, so a residual per
// keypoint poses that chain and nothing else, and only its digit's angles move it.
// pose/fit_kinematics_test.cc holds the two to 1e-9.
#pragma once

#include <array>
#include <cmath>
#include <vector>

#include "format/view.h"
#include "generator/hand/kinematics.h"

namespace handdb {

class FitKinematics {
 public:
  // The rig has been checked by HandRig::Create, so this cannot fail.
  explicit FitKinematics(const HandRig& rig);

  // Keypoint k (docs/conventions.md order) in the hand frame, for `joints` (20, DOF order).
  template <typename T>
  void Keypoint(const T* joints, int k, T* point_in_hand) const {
    Pose(joints, 0, k, point_in_hand);
  }

  // The same from the joints of keypoint k's digit alone (kDigitDofs of them, from DOF
  // DigitOf(k) * kDigitDofs): a digit's keypoints depend on its own angles only, so a solver
  // differentiates with respect to 4 angles instead of 20. The wrist (k = 0) reads none.
  // Valid when digit_blocks() holds.
  template <typename T>
  void KeypointOfDigit(const T* digit_joints, int k, T* point_in_hand) const {
    Pose(digit_joints, DigitOf(k) * kDigitDofs, k, point_in_hand);
  }

  static constexpr int kDigitDofs = 4;
  static constexpr int kNumDigits = kNumJointAngles / kDigitDofs;
  // Keypoint k's digit (docs/conventions.md: thumb 1-4, index 5-8, ..., little 17-20); 0 for the
  // wrist, which has no angle.
  static constexpr int DigitOf(int k) { return k == 0 ? 0 : (k - 1) / kDigitDofs; }

  // KeypointOfDigit in double (the same value, bit for bit), with its derivatives with respect to
  // the digit's angles: jacobian[r][i] = d point[r] / d digit_joints[i], the Jets' dual parts to
  // rounding (a joint turns everything after it about its axis at its bone's origin). Zero for
  // the wrist and for a digit's joints below the keypoint. Valid when digit_blocks() holds.
  void KeypointOfDigitWithJacobian(const double* digit_joints,
                                   int k,
                                   double point_in_hand[3],
                                   double jacobian[3][kDigitDofs]) const;

  // Whether every keypoint's chain turns only by its own digit's DOFs, as docs/conventions.md
  // orders them (digit d: DOFs 4d..4d+3). A rig that breaks this cannot be fitted per digit.
  bool digit_blocks() const { return digit_blocks_; }

  // All 21 keypoints in double, for tests and for the answer of a fit.
  HandKeypoints3d Keypoints3d(const JointVector& joints) const;

 private:
  struct Dof {
    int index = 0;     // in the joint vector
    double axis[3]{};  // unit, bone rest frame
  };
  struct Bone {
    // parent_rest^-1 * rest (the rest transform itself for a root), as rotation and translation.
    double local_rotation[3][3]{};
    double local_translation[3]{};
    std::vector<Dof> dofs;  // abductions then flexions, each in DOF order: R = R(abd) R(flex)
  };
  struct Chain {
    std::vector<int> bones;  // root first, ending at the keypoint's bone
    bool at_tail = false;
    double length = 0;
  };

  // Keypoint k posed from `joints`, whose first entry is DOF `first_dof`. Before each joint turns
  // its bone, on_turn(column, frame, origin, axis) sees the joint's column in `joints`, the bone's
  // rotation so far (bone frame -> hand frame), the bone's origin in the hand frame and the
  // joint's unit axis in bone coordinates.
  template <typename T, typename OnTurn>
  void Pose(const T* joints, int first_dof, int k, T* point_in_hand, OnTurn&& on_turn) const;
  template <typename T>
  void Pose(const T* joints, int first_dof, int k, T* point_in_hand) const {
    Pose(joints,
         first_dof,
         k,
         point_in_hand,
         [](int, const T(&)[3][3], const T(&)[3], const double(&)[3]) {});
  }

  std::vector<Bone> bones_;
  std::array<Chain, kNumKeypoints> chains_;
  bool digit_blocks_ = true;
};

namespace fit_internal {

// out = a * b for 3x3 row-major matrices of possibly different scalars.
template <typename T, typename A, typename B>
void MatMul3(const A (&a)[3][3], const B (&b)[3][3], T (&out)[3][3]) {
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      out[r][c] = a[r][0] * b[0][c] + a[r][1] * b[1][c] + a[r][2] * b[2][c];
    }
  }
}

// Rotation by `angle` about the unit `axis` (Rodrigues), as Eigen::AngleAxis builds it.
template <typename T>
void AxisAngleRotation(const double (&axis)[3], const T& angle, T (&r)[3][3]) {
  using std::cos;
  using std::sin;
  const T c = cos(angle);
  const T s = sin(angle);
  const T one_c = T(1.0) - c;
  const double x = axis[0], y = axis[1], z = axis[2];
  r[0][0] = c + one_c * (x * x);
  r[0][1] = one_c * (x * y) - s * z;
  r[0][2] = one_c * (x * z) + s * y;
  r[1][0] = one_c * (x * y) + s * z;
  r[1][1] = c + one_c * (y * y);
  r[1][2] = one_c * (y * z) - s * x;
  r[2][0] = one_c * (x * z) - s * y;
  r[2][1] = one_c * (y * z) + s * x;
  r[2][2] = c + one_c * (z * z);
}

}  // namespace fit_internal

template <typename T, typename OnTurn>
void FitKinematics::Pose(
    const T* joints, int first_dof, int k, T* point_in_hand, OnTurn&& on_turn) const {
  const Chain& chain = chains_[k];
  // The posed transform of the chain so far (bone frame -> hand frame).
  T rotation[3][3];
  T translation[3];
  bool first = true;
  for (const int b : chain.bones) {
    const Bone& bone = bones_[b];
    // posed = parent_posed * local * R(dofs)
    T with_local[3][3];
    if (first) {
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) with_local[r][c] = T(bone.local_rotation[r][c]);
        translation[r] = T(bone.local_translation[r]);
      }
      first = false;
    } else {
      T moved[3];
      for (int r = 0; r < 3; ++r) {
        moved[r] = translation[r] + rotation[r][0] * bone.local_translation[0] +
                   rotation[r][1] * bone.local_translation[1] +
                   rotation[r][2] * bone.local_translation[2];
      }
      for (int r = 0; r < 3; ++r) translation[r] = moved[r];
      fit_internal::MatMul3(rotation, bone.local_rotation, with_local);
    }
    for (const Dof& dof : bone.dofs) {
      on_turn(dof.index - first_dof, with_local, translation, dof.axis);
      T turn[3][3];
      T turned[3][3];
      fit_internal::AxisAngleRotation(dof.axis, joints[dof.index - first_dof], turn);
      fit_internal::MatMul3(with_local, turn, turned);
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) with_local[r][c] = turned[r][c];
      }
    }
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) rotation[r][c] = with_local[r][c];
    }
  }
  for (int r = 0; r < 3; ++r) {
    point_in_hand[r] =
        chain.at_tail ? translation[r] + rotation[r][1] * chain.length : translation[r];
  }
}

}  // namespace handdb
