// The hand model (configs/hands/*.json, schemas/hand_model.schema.json) and the basic-shape
// library (configs/shapes/*.json, schemas/shapes.schema.json) as the C++ side needs them: joint
// names and limits in the DOF order of docs/conventions.md, links, joint pairs, and the sha256 of
// the file (recorded in plans and shards so a database names the exact hand it was made from).
#pragma once

#include <array>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "base/status.h"
#include "format/view.h"
#include "generator/plan/plan.h"

namespace handdb {

struct HandDof {
  int index = 0;
  std::string name;   // e.g. "thumb_cmc_flexion"
  std::string joint;  // e.g. "thumb_cmc"
  std::string bone;
  std::string kind;  // "flexion" or "abduction"
  std::array<double, 3> axis{};
  double min = 0;
  double max = 0;
};

// A bone of the rigged asset at rest, in the hand frame (armature space).
struct HandBone {
  std::string name;
  std::string parent;  // empty: a root
  int link = 0;
  std::array<double, 3> head{};
  // Row-major; its columns are the bone's x, y (along the bone), z axes in the hand frame.
  std::array<std::array<double, 3>, 3> rest_matrix{};
};

// Where keypoint `index` sits: a bone's head, or `length` along its posed y axis ("tail").
struct HandKeypoint {
  int index = 0;
  std::string name;
  std::string bone;
  bool at_tail = false;
  double length = 0;
  int link = 0;
};

struct HandLink {
  int id = 0;
  std::string name;
  std::vector<std::string> bones;
};

struct HandModel {
  std::filesystem::path path;  // the file it was read from
  std::string sha256;          // of that file's bytes
  std::string name;
  std::string asset_path;  // as written (repository-relative or absolute)
  std::string asset_sha256;
  double ortho_scale = 0;  // the model's recommended orthographic scale (0: none given)
  // The camera references of docs/conventions.md, in the hand frame.
  std::array<double, 3> forward_axis{};
  std::array<double, 3> palm_normal{};
  std::array<double, 3> look_at{};
  std::vector<HandBone> bones;                   // as listed in the file
  std::vector<HandLink> links;                   // ids 1..16 in order
  std::vector<HandDof> dofs;                     // 20, in DOF order
  std::vector<std::pair<int, int>> joint_pairs;  // (parent link, child link)
  std::vector<std::string> keypoint_names;       // 21
  std::vector<HandKeypoint> keypoints;           // 21, as listed (index says which keypoint)

  JointLimits limits() const;
  bool IsJointPair(int link_a, int link_b) const;  // either order
};

// Errors name the file: kNotFound, kBadJson, kSchemaViolation (wrong/missing fields, DOFs not 20
// in order, limits min > max, link ids not 1..16, ...).
Result<HandModel> LoadHandModel(const std::filesystem::path& path);

struct NamedShape {
  std::string name;
  std::string description;
  JointVector joints{};
};

// Reads a shapes file; every shape must be within `limits` (kOutOfRange names the shape and DOF)
// and names must be unique.
Result<std::vector<NamedShape>> LoadShapes(const std::filesystem::path& path,
                                           const JointLimits& limits);

}  // namespace handdb
