// Forward kinematics of the hand model (configs/hands/*.json): the same bones, rest pose, DOF
// axes, rotation order and keypoint definitions that the Blender scripts pose
// (blender_scripts/handdb_blender/kinematics.py), so the query side computes the 21 keypoints of
// any joint-angle vector in the hand frame exactly as the renders were made (docs/hand_model.md).
//
// Each DOF turns its bone about an axis given in the bone's rest frame. A bone with two DOFs
// applies abduction then flexion, R = R(abduction) R(flexion), so flexion turns about the abducted
// bone's own axis; a bone's posed transform (bone frame -> hand frame) is
// parent_pose * parent_rest^-1 * rest * R, which is what Blender computes for a pose bone whose
// rotation is R.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/view.h"
#include "generator/hand/hand_model.h"

namespace handdb {

using Vec3d = std::array<double, 3>;
using Mat3d = std::array<Vec3d, 3>;  // row-major
using HandKeypoints3d = std::array<Vec3d, kNumKeypoints>;

// A posed bone: rotation (columns = the bone's axes in the hand frame) and head position.
struct BonePose {
  Mat3d rotation{};
  Vec3d head{};
};

class HandRig {
 public:
  // Checks what the schema cannot: bone names unique, every parent known, no cycle, at least one
  // root; every DOF on a known bone with a non-zero axis; keypoint indices 0..20 each once, on
  // known bones, "tail" keypoints with a length. Errors (kSchemaViolation) name the model's file.
  static Result<HandRig> Create(const HandModel& model);

  // 21 keypoints (docs/conventions.md order) in the hand frame for `joints` (radians, DOF order).
  // Joints outside the limits are posed as given; see OutsideLimits / limits().Clamp.
  HandKeypoints3d Keypoints3d(const JointVector& joints) const;
  // Every bone's posed transform, in the order of model().bones.
  std::vector<BonePose> PoseBones(const JointVector& joints) const;

  const JointLimits& limits() const { return limits_; }
  // DOF indices whose value lies outside [min - tolerance, max + tolerance], in DOF order.
  std::vector<int> OutsideLimits(const JointVector& joints, double tolerance = 1e-9) const;

  const HandModel& model() const { return model_; }
  const Vec3d& forward_axis() const { return model_.forward_axis; }
  const Vec3d& palm_normal() const { return model_.palm_normal; }
  const Vec3d& look_at() const { return model_.look_at; }

 private:
  struct Dof {
    int bone = -1;
    bool abduction = false;
    Vec3d axis{};  // unit, bone rest frame
  };
  struct Keypoint {
    int bone = -1;
    bool at_tail = false;
    double length = 0;
  };

  HandModel model_;
  JointLimits limits_;
  std::vector<int> parent_;          // per bone, -1 for a root
  std::vector<int> order_;           // bone indices, every parent before its children
  std::vector<Dof> dofs_;            // DOF order
  std::vector<Keypoint> keypoints_;  // by keypoint index
};

}  // namespace handdb
