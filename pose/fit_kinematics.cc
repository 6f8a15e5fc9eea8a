#include "pose/fit_kinematics.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <map>
#include <string>

#include "base/status.h"

namespace handdb {
namespace {

Eigen::Matrix4d RestTransform(const HandBone& bone) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = bone.rest_matrix[r][c];
    m(r, 3) = bone.head[r];
  }
  return m;
}

}  // namespace

FitKinematics::FitKinematics(const HandRig& rig) {
  const HandModel& model = rig.model();
  std::map<std::string, int> index_of;
  for (size_t i = 0; i < model.bones.size(); ++i) {
    index_of.emplace(model.bones[i].name, static_cast<int>(i));
  }
  std::vector<int> parent(model.bones.size(), -1);
  bones_.resize(model.bones.size());
  for (size_t i = 0; i < model.bones.size(); ++i) {
    const HandBone& bone = model.bones[i];
    Eigen::Matrix4d local = RestTransform(bone);
    if (!bone.parent.empty()) {
      parent[i] = index_of.at(bone.parent);
      local = RestTransform(model.bones[parent[i]]).inverse() * local;
    }
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) bones_[i].local_rotation[r][c] = local(r, c);
      bones_[i].local_translation[r] = local(r, 3);
    }
  }
  // Abductions before flexions, each group in DOF order, as HandRig::PoseBones multiplies them.
  for (const bool abduction : {true, false}) {
    for (size_t d = 0; d < model.dofs.size(); ++d) {
      const HandDof& dof = model.dofs[d];
      if ((dof.kind == "abduction") != abduction) continue;
      const double norm = std::sqrt(dof.axis[0] * dof.axis[0] + dof.axis[1] * dof.axis[1] +
                                    dof.axis[2] * dof.axis[2]);
      Dof out;
      out.index = static_cast<int>(d);
      for (int r = 0; r < 3; ++r) out.axis[r] = dof.axis[r] / norm;
      bones_[index_of.at(dof.bone)].dofs.push_back(out);
    }
  }
  for (const HandKeypoint& kp : model.keypoints) {
    Chain& chain = chains_[kp.index];
    for (int b = index_of.at(kp.bone); b >= 0; b = parent[b]) chain.bones.push_back(b);
    std::reverse(chain.bones.begin(), chain.bones.end());
    chain.at_tail = kp.at_tail;
    chain.length = kp.length;
  }
  for (int k = 0; k < kNumKeypoints; ++k) {
    const int first = DigitOf(k) * kDigitDofs;
    for (const int b : chains_[k].bones) {
      for (const Dof& dof : bones_[b].dofs) {
        if (k == 0 || dof.index < first || dof.index >= first + kDigitDofs) digit_blocks_ = false;
      }
    }
  }
}

void FitKinematics::KeypointOfDigitWithJacobian(const double* digit_joints,
                                                int k,
                                                double point_in_hand[3],
                                                double jacobian[3][kDigitDofs]) const {
  // Each turn's bone frame F (before the turn), origin o and axis a. With the keypoint at
  // p = o + F R(a, t) v, d p / d t = F (a x R(a, t) v) = F (a x F^-1 (p - o)). The rig's rest
  // frames are orthonormal only to float precision, so F is inverted, not transposed.
  struct Turn {
    int column;
    double frame[3][3];
    double origin[3];
    double axis[3];
  };
  std::array<Turn, kDigitDofs> turns;
  int num_turns = 0;
  Pose(digit_joints,
       DigitOf(k) * kDigitDofs,
       k,
       point_in_hand,
       [&](int column,
           const double(&frame)[3][3],
           const double(&origin)[3],
           const double(&axis)[3]) {
         // A digit's chain turns by its own joints only, each once (digit_blocks()).
         THROW_CHECK(num_turns < kDigitDofs && column >= 0 && column < kDigitDofs);
         Turn& turn = turns[num_turns++];
         turn.column = column;
         for (int r = 0; r < 3; ++r) {
           for (int c = 0; c < 3; ++c) turn.frame[r][c] = frame[r][c];
           turn.origin[r] = origin[r];
           turn.axis[r] = axis[r];
         }
       });
  for (int r = 0; r < 3; ++r) {
    for (int i = 0; i < kDigitDofs; ++i) jacobian[r][i] = 0;
  }
  using RowMajor3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  const Eigen::Map<const Eigen::Vector3d> p(point_in_hand);
  for (int t = 0; t < num_turns; ++t) {
    const Turn& turn = turns[t];
    const Eigen::Map<const RowMajor3d> f(&turn.frame[0][0]);
    const Eigen::Map<const Eigen::Vector3d> a(turn.axis), o(turn.origin);
    const Eigen::Vector3d column = f * a.cross(f.inverse() * (p - o));
    for (int r = 0; r < 3; ++r) jacobian[r][turn.column] += column[r];
  }
}

HandKeypoints3d FitKinematics::Keypoints3d(const JointVector& joints) const {
  HandKeypoints3d out{};
  for (int k = 0; k < kNumKeypoints; ++k) Keypoint(joints.data(), k, out[k].data());
  return out;
}

}  // namespace handdb
