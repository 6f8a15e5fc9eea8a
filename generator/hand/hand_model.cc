#include "generator/hand/hand_model.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/sha256.h"

namespace handdb {
namespace {

using nlohmann::json;

// Thrown inside this file only, turned into a Status at the API boundary.
struct FieldError {
  std::string message;
};

const json& Field(const json& obj, const char* key, const std::string& where) {
  if (!obj.is_object()) throw FieldError{where + ": expected an object"};
  auto it = obj.find(key);
  if (it == obj.end()) throw FieldError{where + ": missing '" + key + "'"};
  return *it;
}

double Number(const json& v, const std::string& where) {
  if (!v.is_number()) throw FieldError{where + ": expected a number, got " + v.dump()};
  const double d = v.get<double>();
  if (!std::isfinite(d)) throw FieldError{where + ": not finite"};
  return d;
}

int Integer(const json& v, const std::string& where) {
  if (!v.is_number_integer()) throw FieldError{where + ": expected an integer, got " + v.dump()};
  return v.get<int>();
}

std::string String(const json& v, const std::string& where) {
  if (!v.is_string()) throw FieldError{where + ": expected a string, got " + v.dump()};
  return v.get<std::string>();
}

const json& Array(const json& v, const std::string& where) {
  if (!v.is_array()) throw FieldError{where + ": expected an array"};
  return v;
}

std::array<double, 3> Vec3(const json& v, const std::string& where) {
  Array(v, where);
  if (v.size() != 3)
    throw FieldError{where + ": expected 3 numbers, got " + std::to_string(v.size())};
  return {Number(v[0], where + "/0"), Number(v[1], where + "/1"), Number(v[2], where + "/2")};
}

}  // namespace

JointLimits HandModel::limits() const {
  JointLimits l;
  for (int i = 0; i < kNumJointAngles; ++i) {
    l.min[i] = dofs[static_cast<size_t>(i)].min;
    l.max[i] = dofs[static_cast<size_t>(i)].max;
  }
  return l;
}

bool HandModel::IsJointPair(int link_a, int link_b) const {
  for (const auto& [p, c] : joint_pairs) {
    if ((p == link_a && c == link_b) || (p == link_b && c == link_a)) return true;
  }
  return false;
}

Result<HandModel> LoadHandModel(const std::filesystem::path& path) {
  Result<std::string> text = ReadFileToString(path);
  if (!text.ok()) return text.status();
  Result<json> doc = ReadJsonFile(path, "");
  if (!doc.ok()) return doc.status();
  HANDDB_RETURN_IF_ERROR(ValidateJson(*doc, "hand_model.schema.json", path.string()));
  const std::string file = path.string();
  HandModel model;
  model.path = path;
  model.sha256 = Sha256Hex(*text);
  try {
    const json& d = *doc;
    if (String(Field(d, "format", file), file + ": format") != "handdb-hand-model") {
      throw FieldError{file + ": format is not \"handdb-hand-model\""};
    }
    model.name = String(Field(d, "name", file), file + ": name");
    const json& asset = Field(d, "asset", file);
    model.asset_path = String(Field(asset, "path", file + ": asset"), file + ": asset/path");
    if (asset.contains("sha256"))
      model.asset_sha256 = String(asset["sha256"], file + ": asset/sha256");
    if (d.contains("ortho_scale")) {
      model.ortho_scale = Number(d["ortho_scale"], file + ": ortho_scale");
      if (model.ortho_scale <= 0) throw FieldError{file + ": ortho_scale must be > 0"};
    }

    if (d.contains("forward_axis"))
      model.forward_axis = Vec3(d["forward_axis"], file + ": forward_axis");
    if (d.contains("palm_normal"))
      model.palm_normal = Vec3(d["palm_normal"], file + ": palm_normal");
    if (d.contains("look_at")) model.look_at = Vec3(d["look_at"], file + ": look_at");
    if (d.contains("bones")) {
      const json& bones = Array(d["bones"], file + ": bones");
      for (size_t i = 0; i < bones.size(); ++i) {
        const std::string where = file + ": bones/" + std::to_string(i);
        HandBone bone;
        bone.name = String(Field(bones[i], "name", where), where + "/name");
        const json& parent = Field(bones[i], "parent", where);
        if (!parent.is_null()) bone.parent = String(parent, where + "/parent");
        bone.link = Integer(Field(bones[i], "link", where), where + "/link");
        bone.head = Vec3(Field(bones[i], "head", where), where + "/head");
        const json& rest = Array(Field(bones[i], "rest_matrix", where), where + "/rest_matrix");
        if (rest.size() != 3) throw FieldError{where + "/rest_matrix: expected 3 rows"};
        for (size_t r = 0; r < 3; ++r) {
          bone.rest_matrix[r] = Vec3(rest[r], where + "/rest_matrix/" + std::to_string(r));
        }
        model.bones.push_back(std::move(bone));
      }
    }

    const json& links = Array(Field(d, "links", file), file + ": links");
    for (size_t i = 0; i < links.size(); ++i) {
      const std::string where = file + ": links/" + std::to_string(i);
      HandLink link;
      link.id = Integer(Field(links[i], "id", where), where + "/id");
      link.name = String(Field(links[i], "name", where), where + "/name");
      for (const auto& b : Array(Field(links[i], "bones", where), where + "/bones")) {
        link.bones.push_back(String(b, where + "/bones"));
      }
      if (link.id != static_cast<int>(i) + 1) {
        throw FieldError{where + ": id " + std::to_string(link.id) + ", expected " +
                         std::to_string(i + 1)};
      }
      model.links.push_back(std::move(link));
    }
    if (model.links.size() != kNumLinks) {
      throw FieldError{file + ": links: " + std::to_string(model.links.size()) +
                       " links, expected 16"};
    }

    const json& dofs = Array(Field(d, "dofs", file), file + ": dofs");
    if (dofs.size() != kNumJointAngles) {
      throw FieldError{file + ": dofs: " + std::to_string(dofs.size()) + " DOFs, expected 20"};
    }
    for (size_t i = 0; i < dofs.size(); ++i) {
      const std::string where = file + ": dofs/" + std::to_string(i);
      HandDof dof;
      dof.index = Integer(Field(dofs[i], "index", where), where + "/index");
      dof.name = String(Field(dofs[i], "name", where), where + "/name");
      dof.bone = String(Field(dofs[i], "bone", where), where + "/bone");
      if (dofs[i].contains("joint")) dof.joint = String(dofs[i]["joint"], where + "/joint");
      if (dofs[i].contains("kind")) dof.kind = String(dofs[i]["kind"], where + "/kind");
      dof.axis = Vec3(Field(dofs[i], "axis", where), where + "/axis");
      dof.min = Number(Field(dofs[i], "min", where), where + "/min");
      dof.max = Number(Field(dofs[i], "max", where), where + "/max");
      if (dof.index != static_cast<int>(i)) {
        throw FieldError{where + ": index " + std::to_string(dof.index) + ", expected " +
                         std::to_string(i)};
      }
      if (!(dof.min <= dof.max)) {
        std::ostringstream os;
        os << where << ": min " << dof.min << " > max " << dof.max;
        throw FieldError{os.str()};
      }
      model.dofs.push_back(std::move(dof));
    }

    for (const auto& pair : Array(Field(d, "joint_pairs", file), file + ": joint_pairs")) {
      const std::string where = file + ": joint_pairs";
      if (!pair.is_array() || pair.size() != 2)
        throw FieldError{where + ": expected [parent, child], got " + pair.dump()};
      const int p = Integer(pair[0], where);
      const int c = Integer(pair[1], where);
      if (p < 1 || p > kNumLinks || c < 1 || c > kNumLinks || p == c) {
        throw FieldError{where + ": bad link ids " + pair.dump()};
      }
      model.joint_pairs.emplace_back(p, c);
    }

    if (d.contains("keypoints")) {
      const json& kps = Array(d["keypoints"], file + ": keypoints");
      for (size_t i = 0; i < kps.size(); ++i) {
        const std::string where = file + ": keypoints/" + std::to_string(i);
        HandKeypoint kp;
        kp.name = String(Field(kps[i], "name", where), where + "/name");
        if (kps[i].contains("index")) kp.index = Integer(kps[i]["index"], where + "/index");
        if (kps[i].contains("bone")) kp.bone = String(kps[i]["bone"], where + "/bone");
        if (kps[i].contains("at")) kp.at_tail = String(kps[i]["at"], where + "/at") == "tail";
        if (kps[i].contains("length")) kp.length = Number(kps[i]["length"], where + "/length");
        if (kps[i].contains("link")) kp.link = Integer(kps[i]["link"], where + "/link");
        model.keypoint_names.push_back(kp.name);
        model.keypoints.push_back(std::move(kp));
      }
      if (model.keypoint_names.size() != kNumKeypoints) {
        throw FieldError{file + ": keypoints: " + std::to_string(kps.size()) + ", expected 21"};
      }
    }
  } catch (const FieldError& e) {
    return Status(StatusCode::kSchemaViolation, e.message);
  } catch (const json::exception& e) {
    return Status(StatusCode::kSchemaViolation, file + ": " + e.what());
  }
  return model;
}

Result<std::vector<NamedShape>> LoadShapes(const std::filesystem::path& path,
                                           const JointLimits& limits) {
  Result<json> doc = ReadJsonFile(path, "");
  if (!doc.ok()) return doc.status();
  HANDDB_RETURN_IF_ERROR(ValidateJson(*doc, "shapes.schema.json", path.string()));
  const std::string file = path.string();
  std::vector<NamedShape> shapes;
  try {
    const json& list = Array(Field(*doc, "shapes", file), file + ": shapes");
    std::set<std::string> names;
    for (size_t i = 0; i < list.size(); ++i) {
      const std::string where = file + ": shapes/" + std::to_string(i);
      NamedShape shape;
      shape.name = String(Field(list[i], "name", where), where + "/name");
      if (list[i].contains("description")) {
        shape.description = String(list[i]["description"], where + "/description");
      }
      const json& joints = Array(Field(list[i], "joints", where), where + "/joints");
      if (joints.size() != kNumJointAngles) {
        throw FieldError{where + " ('" + shape.name + "'): " + std::to_string(joints.size()) +
                         " joint angles, expected 20"};
      }
      for (int j = 0; j < kNumJointAngles; ++j) {
        shape.joints[j] = Number(joints[j], where + "/joints/" + std::to_string(j));
        if (shape.joints[j] < limits.min[j] - 1e-9 || shape.joints[j] > limits.max[j] + 1e-9) {
          std::ostringstream os;
          os << where << " ('" << shape.name << "'): joint " << j << " = " << shape.joints[j]
             << " outside the limits [" << limits.min[j] << ", " << limits.max[j] << "]";
          return Status(StatusCode::kOutOfRange, os.str());
        }
      }
      if (!names.insert(shape.name).second) {
        throw FieldError{where + ": duplicate shape name '" + shape.name + "'"};
      }
      shapes.push_back(std::move(shape));
    }
    if (shapes.empty()) throw FieldError{file + ": shapes: empty"};
  } catch (const FieldError& e) {
    return Status(StatusCode::kSchemaViolation, e.message);
  }
  return shapes;
}

}  // namespace handdb
