#include "generator/hand/kinematics.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

namespace handdb {
namespace {

Eigen::Matrix3d DofRotation(const Vec3d& unit_axis, double angle) {
  return Eigen::AngleAxisd(angle, Eigen::Vector3d(unit_axis[0], unit_axis[1], unit_axis[2]))
      .toRotationMatrix();
}

Eigen::Matrix4d BoneRestTransform(const HandBone& bone) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = bone.rest_matrix[r][c];
    m(r, 3) = bone.head[r];
  }
  return m;
}

Status RigError(const HandModel& model, const std::string& problem) {
  return Status(StatusCode::kSchemaViolation, model.path.string() + ": " + problem);
}

}  // namespace

Result<HandRig> HandRig::Create(const HandModel& model) {
  HandRig rig;
  rig.model_ = model;
  if (model.dofs.size() != kNumJointAngles) {
    return RigError(model, std::to_string(model.dofs.size()) + " DOFs, expected 20");
  }
  rig.limits_ = model.limits();
  if (model.bones.empty()) return RigError(model, "bones: none");

  std::map<std::string, int> index_of;
  for (size_t i = 0; i < model.bones.size(); ++i) {
    if (!index_of.emplace(model.bones[i].name, static_cast<int>(i)).second) {
      return RigError(model, "bones: '" + model.bones[i].name + "' appears twice");
    }
  }
  rig.parent_.assign(model.bones.size(), -1);
  for (size_t i = 0; i < model.bones.size(); ++i) {
    const HandBone& bone = model.bones[i];
    if (bone.parent.empty()) continue;
    const auto it = index_of.find(bone.parent);
    if (it == index_of.end()) {
      return RigError(model, "bones: '" + bone.name + "' has unknown parent '" + bone.parent + "'");
    }
    rig.parent_[i] = it->second;
  }
  // Parents first; a bone whose chain of parents is longer than the bone count is in a cycle.
  std::vector<int> depth(model.bones.size(), -1);
  for (size_t i = 0; i < model.bones.size(); ++i) {
    int steps = 0;
    for (int b = static_cast<int>(i); rig.parent_[b] >= 0; b = rig.parent_[b]) {
      if (++steps > static_cast<int>(model.bones.size())) {
        return RigError(model, "bones: the hierarchy has a cycle at '" + model.bones[i].name + "'");
      }
    }
    depth[i] = steps;
  }
  rig.order_.resize(model.bones.size());
  for (size_t i = 0; i < rig.order_.size(); ++i) rig.order_[i] = static_cast<int>(i);
  std::stable_sort(
      rig.order_.begin(), rig.order_.end(), [&](int a, int b) { return depth[a] < depth[b]; });

  for (const HandDof& dof : model.dofs) {
    const auto it = index_of.find(dof.bone);
    if (it == index_of.end()) {
      return RigError(model,
                      "dofs/" + std::to_string(dof.index) + " ('" + dof.name +
                          "'): unknown bone '" + dof.bone + "'");
    }
    const double norm = std::sqrt(dof.axis[0] * dof.axis[0] + dof.axis[1] * dof.axis[1] +
                                  dof.axis[2] * dof.axis[2]);
    if (!(norm > 1e-12)) {
      return RigError(model,
                      "dofs/" + std::to_string(dof.index) + " ('" + dof.name + "'): axis is zero");
    }
    if (dof.kind != "flexion" && dof.kind != "abduction") {
      return RigError(model,
                      "dofs/" + std::to_string(dof.index) + " ('" + dof.name + "'): kind '" +
                          dof.kind + "', expected flexion or abduction");
    }
    rig.dofs_.push_back({it->second,
                         dof.kind == "abduction",
                         {dof.axis[0] / norm, dof.axis[1] / norm, dof.axis[2] / norm}});
  }

  if (model.keypoints.size() != kNumKeypoints) {
    return RigError(model,
                    "keypoints: " + std::to_string(model.keypoints.size()) + ", expected 21");
  }
  rig.keypoints_.assign(kNumKeypoints, Keypoint{});
  for (const HandKeypoint& kp : model.keypoints) {
    const std::string where = "keypoints: '" + kp.name + "'";
    if (kp.index < 0 || kp.index >= kNumKeypoints) {
      return RigError(model, where + ": index " + std::to_string(kp.index) + " not in 0..20");
    }
    if (rig.keypoints_[kp.index].bone >= 0) {
      return RigError(model, where + ": index " + std::to_string(kp.index) + " used twice");
    }
    const auto it = index_of.find(kp.bone);
    if (it == index_of.end()) return RigError(model, where + ": unknown bone '" + kp.bone + "'");
    if (kp.at_tail && !(kp.length > 0)) {
      return RigError(model, where + ": a tail keypoint needs a length > 0");
    }
    rig.keypoints_[kp.index] = {it->second, kp.at_tail, kp.length};
  }
  return rig;
}

std::vector<BonePose> HandRig::PoseBones(const JointVector& joints) const {
  const size_t n = model_.bones.size();
  // Per bone: the product of its abduction rotations and of its flexion rotations, each in DOF
  // order, then R = R(abduction) R(flexion).
  std::vector<std::optional<Eigen::Matrix3d>> abduction(n), flexion(n);
  for (size_t i = 0; i < dofs_.size(); ++i) {
    const Dof& dof = dofs_[i];
    const Eigen::Matrix3d r = DofRotation(dof.axis, joints[i]);
    auto& target = dof.abduction ? abduction[dof.bone] : flexion[dof.bone];
    target = target ? Eigen::Matrix3d(*target * r) : r;
  }
  std::vector<Eigen::Matrix4d> posed(n);
  for (const int b : order_) {
    Eigen::Matrix4d basis = Eigen::Matrix4d::Identity();
    if (abduction[b] || flexion[b]) {
      basis.topLeftCorner<3, 3>() = abduction[b].value_or(Eigen::Matrix3d::Identity()) *
                                    flexion[b].value_or(Eigen::Matrix3d::Identity());
    }
    const Eigen::Matrix4d rest = BoneRestTransform(model_.bones[b]);
    const int p = parent_[b];
    if (p < 0) {
      posed[b] = rest * basis;
    } else {
      const Eigen::Matrix4d parent_rest = BoneRestTransform(model_.bones[p]);
      posed[b] = posed[p] * parent_rest.inverse() * rest * basis;
    }
  }
  std::vector<BonePose> out(n);
  for (size_t b = 0; b < n; ++b) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) out[b].rotation[r][c] = posed[b](r, c);
      out[b].head[r] = posed[b](r, 3);
    }
  }
  return out;
}

HandKeypoints3d HandRig::Keypoints3d(const JointVector& joints) const {
  const std::vector<BonePose> posed = PoseBones(joints);
  HandKeypoints3d out{};
  for (int k = 0; k < kNumKeypoints; ++k) {
    const Keypoint& kp = keypoints_[k];
    const BonePose& bone = posed[kp.bone];
    for (int r = 0; r < 3; ++r) {
      out[k][r] = bone.head[r] + (kp.at_tail ? bone.rotation[r][1] * kp.length : 0.0);
    }
  }
  return out;
}

std::vector<int> HandRig::OutsideLimits(const JointVector& joints, double tolerance) const {
  std::vector<int> bad;
  for (int i = 0; i < kNumJointAngles; ++i) {
    if (!(joints[i] >= limits_.min[i] - tolerance && joints[i] <= limits_.max[i] + tolerance)) {
      bad.push_back(i);
    }
  }
  return bad;
}

}  // namespace handdb
