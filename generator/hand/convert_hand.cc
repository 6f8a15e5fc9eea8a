#include "generator/hand/convert_hand.h"

#include "generator/hand/hand_model.h"

namespace handdb {

Result<ConvertHandInfo> LoadConvertHandInfo(const std::filesystem::path& path) {
  auto hand = LoadHandModel(path);
  if (!hand.ok()) return hand.status();
  ConvertHandInfo info;
  info.name = hand->name;
  info.sha256 = hand->sha256;
  info.joint_pairs = hand->joint_pairs;
  for (const HandDof& dof : hand->dofs) {
    info.dof_names.push_back(dof.name);
    info.dof_limits.emplace_back(dof.min, dof.max);
  }
  info.keypoint_names = hand->keypoint_names;
  return info;
}

}  // namespace handdb
