// What the converter needs from the hand model (generator/hand/hand_model.h), behind a header of plain
// types: joint pairs for the edge rule, DOF names and limits and keypoint names for the shard
// metadata. Kept separate so the converter does not include hand_model.h and format/view.h in one
// translation unit (both define kNumLinks / kNumKeypoints).
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "base/status.h"

namespace handdb {

struct ConvertHandInfo {
  std::string name;
  std::string sha256;  // of the hand-model file
  std::vector<std::pair<int, int>> joint_pairs;
  std::vector<std::string> dof_names;                 // DOF order
  std::vector<std::pair<double, double>> dof_limits;  // [min, max] rad, DOF order
  std::vector<std::string> keypoint_names;
};

// LoadHandModel + the fields above; errors as LoadHandModel's (they name the file).
Result<ConvertHandInfo> LoadConvertHandInfo(const std::filesystem::path& path);

}  // namespace handdb
