#include "pose/export_gltf.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "generator/plan/plan.h"
#include "handdb_version.h"
#include "pose/tiny_gltf_config.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

// The render camera's distance from look_at (blender_scripts/handdb_blender/scene.py
// CAMERA_DISTANCE) and its clipping range; an orthographic image does not depend on the distance.
constexpr double kCameraDistance = 1.0;
constexpr double kCameraZNear = 0.01;
constexpr double kCameraZFar = 2.0 * kCameraDistance + 1.0;
// How far the asset's rest joints may lie from the hand model's bones: the tolerance render.py
// checks the imported asset with, so the export poses the same asset the renders were made from.
constexpr double kRestTolerance = 1e-4;
// An asset larger than this is refused before it is read (the hand is 94 kB).
constexpr uint64_t kMaxAssetBytes = uint64_t{256} << 20;

using Mat4 = Eigen::Matrix4d;

Status Error(StatusCode code, const fs::path& file, const std::string& problem) {
  return Status(code, file.string() + ": " + problem);
}

std::string FirstLine(const std::string& text) {
  const size_t end = text.find('\n');
  return end == std::string::npos ? text : text.substr(0, end);
}

// The hand frame is the armature space of Blender's glTF importer: glTF's +Y up turned to +Z up,
// (x, y, z)_hand = (x, -z, y)_glTF. Bone frames turn with it (a bone's rest_matrix is
// C R_joint C^T), so a transform T in the hand frame is C^T T C in the glTF armature's frame.
Mat4 HandFromGltf() {
  Mat4 c = Mat4::Zero();
  c(0, 0) = 1;
  c(1, 2) = -1;
  c(2, 1) = 1;
  c(3, 3) = 1;
  return c;
}

Mat4 ToMat4(const Mat3d& rotation, const Vec3d& translation) {
  Mat4 m = Mat4::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = rotation[r][c];
    m(r, 3) = translation[r];
  }
  return m;
}

Mat4 NodeLocal(const tinygltf::Node& node) {
  Mat4 m = Mat4::Identity();
  if (node.matrix.size() == 16) {
    for (int i = 0; i < 16; ++i) m(i % 4, i / 4) = node.matrix[i];  // column-major
    return m;
  }
  if (node.scale.size() == 3) m.diagonal().head<3>() = Eigen::Vector3d(node.scale.data());
  if (node.rotation.size() == 4) {
    const Eigen::Quaterniond q(
        node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
    m.topLeftCorner<3, 3>() = q.normalized().toRotationMatrix() * m.topLeftCorner<3, 3>();
  }
  if (node.translation.size() == 3) m.col(3).head<3>() = Eigen::Vector3d(node.translation.data());
  return m;
}

// The nodes' parents (-1: a root); kSchemaViolation for a node with two parents or a bad index.
Result<std::vector<int>> NodeParents(const tinygltf::Model& model, const fs::path& asset) {
  const int n = static_cast<int>(model.nodes.size());
  std::vector<int> parent(n, -1);
  for (int i = 0; i < n; ++i) {
    for (const int child : model.nodes[i].children) {
      if (child < 0 || child >= n || parent[child] >= 0) {
        return Error(StatusCode::kSchemaViolation,
                     asset,
                     "node " + std::to_string(i) + " has child " + std::to_string(child) +
                         ", which is out of range or has another parent");
      }
      parent[child] = i;
    }
  }
  return parent;
}

// A node's world matrix; kSchemaViolation when its chain of parents is a cycle.
Result<Mat4> NodeWorld(const tinygltf::Model& model,
                       const std::vector<int>& parent,
                       int node,
                       const fs::path& file) {
  Mat4 world = Mat4::Identity();
  int steps = 0;
  for (int i = node; i >= 0; i = parent[i]) {
    if (++steps > static_cast<int>(model.nodes.size())) {
      return Error(StatusCode::kSchemaViolation, file, "the node hierarchy has a cycle");
    }
    world = NodeLocal(model.nodes[i]) * world;
  }
  return world;
}

// The images stay the bytes they are in their buffer: the writer refers to them as it found them.
bool KeepImageBytes(tinygltf::Image*,
                    const int,
                    std::string*,
                    std::string*,
                    int,
                    int,
                    const unsigned char*,
                    int,
                    void*) {
  return true;
}

Result<tinygltf::Model> LoadAsset(const fs::path& asset) {
  Result<std::string> bytes = ReadFileToString(asset, kMaxAssetBytes);
  if (!bytes.ok()) return bytes.status();
  if (bytes->size() < 12 || bytes->compare(0, 4, "glTF") != 0) {
    return Error(StatusCode::kBadMagic, asset, "not a glTF binary (no 'glTF' magic)");
  }
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(KeepImageBytes, nullptr);
  tinygltf::Model model;
  std::string err, warn;
  const bool ok = loader.LoadBinaryFromMemory(&model,
                                              &err,
                                              &warn,
                                              reinterpret_cast<const unsigned char*>(bytes->data()),
                                              static_cast<unsigned int>(bytes->size()),
                                              asset.parent_path().string());
  if (!ok) {
    return Error(StatusCode::kSchemaViolation,
                 asset,
                 "not a loadable glTF: " + FirstLine(err.empty() ? warn : err));
  }
  return model;
}

// The skin joint node of each of the rig's bones, by name (model().bones order).
Result<std::vector<int>> JointNodes(const tinygltf::Model& model,
                                    const HandModel& hand,
                                    const fs::path& asset) {
  std::map<std::string, int> by_name;
  for (const tinygltf::Skin& skin : model.skins) {
    for (const int joint : skin.joints) {
      if (joint < 0 || joint >= static_cast<int>(model.nodes.size())) {
        return Error(StatusCode::kSchemaViolation,
                     asset,
                     "skin '" + skin.name + "' names node " + std::to_string(joint) +
                         ", which does not exist");
      }
      const auto [it, inserted] = by_name.emplace(model.nodes[joint].name, joint);
      if (!inserted && it->second != joint) {
        return Error(StatusCode::kSchemaViolation,
                     asset,
                     "two skin joints are named '" + model.nodes[joint].name + "'");
      }
    }
  }
  std::vector<int> nodes;
  for (const HandBone& bone : hand.bones) {
    const auto it = by_name.find(bone.name);
    if (it == by_name.end()) {
      return Error(StatusCode::kSchemaViolation,
                   asset,
                   "no skin joint named '" + bone.name + "', a bone of " + hand.path.string());
    }
    nodes.push_back(it->second);
  }
  return nodes;
}

// Bone indices, every parent before its children (HandRig::Create has ruled out cycles).
std::vector<int> ParentsFirst(const HandModel& hand, std::vector<int>* bone_parent) {
  std::map<std::string, int> index_of;
  for (size_t i = 0; i < hand.bones.size(); ++i) index_of[hand.bones[i].name] = static_cast<int>(i);
  bone_parent->assign(hand.bones.size(), -1);
  for (size_t i = 0; i < hand.bones.size(); ++i) {
    if (!hand.bones[i].parent.empty()) (*bone_parent)[i] = index_of.at(hand.bones[i].parent);
  }
  std::vector<int> depth(hand.bones.size(), 0);
  for (size_t i = 0; i < hand.bones.size(); ++i) {
    for (int b = (*bone_parent)[i]; b >= 0; b = (*bone_parent)[b]) ++depth[i];
  }
  std::vector<int> order(hand.bones.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return depth[a] < depth[b]; });
  return order;
}

std::string Format(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.3g", value);
  return buffer;
}

// The asset's rest joints (in the armature's frame) against the hand model's bones.
Status CheckRest(const HandModel& hand,
                 const std::vector<Mat4>& rest_in_armature,
                 const fs::path& asset) {
  const Mat4 c = HandFromGltf();
  for (size_t b = 0; b < hand.bones.size(); ++b) {
    const Mat4 expected = ToMat4(hand.bones[b].rest_matrix, hand.bones[b].head);
    const double off = (c * rest_in_armature[b] * c.transpose() - expected).cwiseAbs().maxCoeff();
    if (!(off <= kRestTolerance)) {
      return Error(StatusCode::kSchemaViolation,
                   asset,
                   "joint '" + hand.bones[b].name + "' rests " + Format(off) +
                       " from the bone of " + hand.path.string() + " (tolerance " +
                       Format(kRestTolerance) + "): another asset than the hand model's");
    }
  }
  return Status::Ok();
}

void SetRigidLocal(const Mat4& local, tinygltf::Node* node) {
  Eigen::Quaterniond q(Eigen::Matrix3d(local.topLeftCorner<3, 3>()));
  q.normalize();
  node->matrix.clear();
  node->scale.clear();
  node->rotation = {q.x(), q.y(), q.z(), q.w()};
  node->translation = {local(0, 3), local(1, 3), local(2, 3)};
}

void Reparent(int node, int new_parent, std::vector<int>* parent, tinygltf::Model* model) {
  const int old_parent = (*parent)[node];
  if (old_parent == new_parent) return;
  auto drop = [node](std::vector<int>* list) {
    list->erase(std::remove(list->begin(), list->end(), node), list->end());
  };
  if (old_parent >= 0) {
    drop(&model->nodes[old_parent].children);
  } else {
    for (tinygltf::Scene& scene : model->scenes) drop(&scene.nodes);
  }
  model->nodes[new_parent].children.push_back(node);
  (*parent)[node] = new_parent;
}

// An orthographic camera placed as the render camera: at look_at + distance * view direction,
// looking along cam_from_hand's z; glTF's camera looks along its -z with +y up, so its axes in the
// hand frame are (x, -y, -z) of the render camera's.
void AddCamera(const Mat3d& cam_from_hand,
               const Vec3d& look_at,
               double ortho_scale,
               int armature,
               tinygltf::Model* model) {
  tinygltf::Camera camera;
  camera.name = "render camera";
  camera.type = "orthographic";
  camera.orthographic.xmag = ortho_scale / 2;
  camera.orthographic.ymag = ortho_scale / 2;
  camera.orthographic.znear = kCameraZNear;
  camera.orthographic.zfar = kCameraZFar;
  model->cameras.push_back(camera);

  Mat4 in_hand = Mat4::Identity();
  const double flip[3] = {1, -1, -1};
  for (int axis = 0; axis < 3; ++axis) {
    for (int r = 0; r < 3; ++r) in_hand(r, axis) = flip[axis] * cam_from_hand[axis][r];
  }
  for (int r = 0; r < 3; ++r) {
    in_hand(r, 3) = look_at[r] - kCameraDistance * cam_from_hand[2][r];
  }
  tinygltf::Node node;
  node.name = "render camera";
  node.camera = static_cast<int>(model->cameras.size()) - 1;
  SetRigidLocal(HandFromGltf().transpose() * in_hand, &node);
  model->nodes.push_back(node);
  const int index = static_cast<int>(model->nodes.size()) - 1;
  if (armature >= 0) {
    model->nodes[armature].children.push_back(index);
  } else {
    const int scene = std::max(model->defaultScene, 0);
    if (model->scenes.empty()) model->scenes.emplace_back();
    model->scenes[scene].nodes.push_back(index);
  }
}

// The reflection across the plane through `point` normal to `normal` (hand frame), in the glTF
// armature's axes.
Mat4 MirrorInArmature(const Vec3d& normal, const Vec3d& point) {
  const Eigen::Vector3d n = Eigen::Vector3d(normal.data()).normalized();
  Mat4 m = Mat4::Identity();
  m.topLeftCorner<3, 3>() -= 2 * n * n.transpose();
  m.col(3).head<3>() = 2 * n.dot(Eigen::Vector3d(point.data())) * n;
  return HandFromGltf().transpose() * m * HandFromGltf();
}

// Element `i` of `accessor` as `count` floats, or null when its bytes are not there.
float* AccessorFloats(tinygltf::Model* model, const tinygltf::Accessor& accessor, size_t i) {
  if (accessor.bufferView < 0 ||
      accessor.bufferView >= static_cast<int>(model->bufferViews.size())) {
    return nullptr;
  }
  const tinygltf::BufferView& view = model->bufferViews[accessor.bufferView];
  const int size = tinygltf::GetComponentSizeInBytes(accessor.componentType) *
                   tinygltf::GetNumComponentsInType(accessor.type);
  const size_t stride = view.byteStride > 0 ? view.byteStride : static_cast<size_t>(size);
  const size_t offset = view.byteOffset + accessor.byteOffset + i * stride;
  if (view.buffer < 0 || view.buffer >= static_cast<int>(model->buffers.size()) || size <= 0 ||
      offset + size > model->buffers[view.buffer].data.size()) {
    return nullptr;
  }
  return reinterpret_cast<float*>(model->buffers[view.buffer].data.data() + offset);
}

// The skin's data mirrored in bind space, x -> -x: vertex positions, normals and tangents (whose
// w, the bitangent's handedness, turns too), the triangles' winding, and the inverse bind
// matrices conjugated by diag(-1, 1, 1). With each joint posed at mirror * pose * diag(-1, 1, 1),
// joint world x inverse bind x vertex is then the mirror of the right hand's skinned vertex, and
// every transform in the file stays a rotation: no viewer has to handle a negative scale.
Status MirrorSkinData(int skin, const fs::path& asset, tinygltf::Model* model) {
  auto unsupported = [&](const std::string& what) {
    return Error(StatusCode::kSchemaViolation, asset, "cannot mirror " + what + " for a left hand");
  };
  std::vector<bool> done(model->accessors.size(), false);
  auto mirror = [&](int index, int type, const std::string& what) -> Status {
    if (index < 0 || index >= static_cast<int>(model->accessors.size())) {
      return unsupported(what + " (no such accessor)");
    }
    if (done[index]) return Status::Ok();
    done[index] = true;
    tinygltf::Accessor& accessor = model->accessors[index];
    if (accessor.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT || accessor.type != type ||
        accessor.sparse.isSparse) {
      return unsupported(what + " that is not plain float data");
    }
    for (size_t i = 0; i < accessor.count; ++i) {
      float* v = AccessorFloats(model, accessor, i);
      if (v == nullptr) return unsupported(what + " whose bytes lie outside its buffer");
      if (type == TINYGLTF_TYPE_MAT4) {
        for (int k = 0; k < 16; ++k) {
          if ((k % 4 == 0) != (k / 4 == 0)) v[k] = -v[k];  // column-major (row 0) xor (col 0)
        }
      } else {
        v[0] = -v[0];
        if (type == TINYGLTF_TYPE_VEC4) v[3] = -v[3];
      }
    }
    if (what == "POSITION" && accessor.minValues.size() == 3 && accessor.maxValues.size() == 3) {
      const double min_x = accessor.minValues[0];
      accessor.minValues[0] = -accessor.maxValues[0];
      accessor.maxValues[0] = -min_x;
    }
    return Status::Ok();
  };
  auto flip_winding = [&](int index) -> Status {
    if (done[index]) return Status::Ok();
    done[index] = true;
    const tinygltf::Accessor& accessor = model->accessors[index];
    const int size = tinygltf::GetComponentSizeInBytes(accessor.componentType);
    if (accessor.bufferView < 0 || accessor.sparse.isSparse || accessor.count % 3 != 0 ||
        (size != 1 && size != 2 && size != 4)) {
      return unsupported("triangle indices of this kind");
    }
    const tinygltf::BufferView& view = model->bufferViews.at(accessor.bufferView);
    const size_t offset = view.byteOffset + accessor.byteOffset;
    std::vector<unsigned char>& bytes = model->buffers.at(view.buffer).data;
    if (view.byteStride > 0 && view.byteStride != static_cast<size_t>(size)) {
      return unsupported("strided triangle indices");
    }
    if (offset + accessor.count * size > bytes.size()) {
      return unsupported("triangle indices outside their buffer");
    }
    for (size_t t = 0; t < accessor.count; t += 3) {
      std::swap_ranges(bytes.begin() + offset + (t + 1) * size,
                       bytes.begin() + offset + (t + 2) * size,
                       bytes.begin() + offset + (t + 2) * size);
    }
    return Status::Ok();
  };

  for (const tinygltf::Node& node : model->nodes) {
    if (node.skin != skin || node.mesh < 0) continue;
    for (const tinygltf::Primitive& primitive : model->meshes.at(node.mesh).primitives) {
      if (primitive.mode != TINYGLTF_MODE_TRIANGLES || primitive.indices < 0) {
        return unsupported("a primitive that is not indexed triangles");
      }
      if (!primitive.targets.empty()) return unsupported("morph targets");
      HANDDB_RETURN_IF_ERROR(flip_winding(primitive.indices));
      for (const auto& [name, index] : primitive.attributes) {
        if (name == "POSITION" || name == "NORMAL") {
          HANDDB_RETURN_IF_ERROR(mirror(index, TINYGLTF_TYPE_VEC3, name));
        } else if (name == "TANGENT") {
          HANDDB_RETURN_IF_ERROR(mirror(index, TINYGLTF_TYPE_VEC4, name));
        }
      }
    }
  }
  return mirror(
      model->skins[skin].inverseBindMatrices, TINYGLTF_TYPE_MAT4, "inverse bind matrices");
}

}  // namespace

bool PosedHandGlbOptions::Check() const {
  CHECK_OPTION(std::isfinite(ortho_scale) && ortho_scale >= 0);
  if (cam_from_hand) {
    const Mat3d& r = *cam_from_hand;
    Eigen::Matrix3d m;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) m(i, j) = r[i][j];
    }
    CHECK_OPTION(m.allFinite());
    CHECK_OPTION((m * m.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <= 1e-6);
    CHECK_OPTION(m.determinant() > 0);
  }
  return true;
}

Status WritePosedHandGlb(const fs::path& out,
                         const HandRig& rig,
                         const JointVector& joints,
                         const PosedHandGlbOptions& options) {
  const HandModel& hand = rig.model();
  if (!options.Check()) {
    return Error(StatusCode::kInvalidArgument, out, "export options fail their checks (see above)");
  }
  for (int i = 0; i < kNumJointAngles; ++i) {
    if (!std::isfinite(joints[i])) {
      return Error(StatusCode::kInvalidArgument,
                   out,
                   "joint " + std::to_string(i) + " ('" + hand.dofs[i].name + "') is not finite");
    }
  }
  const double ortho_scale = options.ortho_scale > 0 ? options.ortho_scale : hand.ortho_scale;
  if (options.cam_from_hand && !(ortho_scale > 0)) {
    return Error(StatusCode::kInvalidArgument,
                 out,
                 "a camera needs an ortho_scale, and " + hand.path.string() + " gives none");
  }
  fs::path asset = options.asset;
  if (asset.empty()) {
    if (hand.asset_path.empty()) {
      return Error(StatusCode::kInvalidArgument, hand.path, "names no asset to export");
    }
    asset = ResolvePlanPath(hand.asset_path);
  }

  Result<tinygltf::Model> loaded = LoadAsset(asset);
  if (!loaded.ok()) return loaded.status();
  tinygltf::Model& model = *loaded;
  Result<std::vector<int>> parents = NodeParents(model, asset);
  if (!parents.ok()) return parents.status();
  std::vector<int>& parent = *parents;
  Result<std::vector<int>> nodes = JointNodes(model, hand, asset);
  if (!nodes.ok()) return nodes.status();
  const std::vector<int>& node_of = *nodes;

  std::vector<int> bone_parent;
  const std::vector<int> order = ParentsFirst(hand, &bone_parent);
  // The armature: the node that holds the rig's root joint; its frame is the hand frame in glTF's
  // axes (identity when the root joint is a scene root).
  const int armature = parent[node_of[order[0]]];
  Mat4 armature_world = Mat4::Identity();
  if (armature >= 0) {
    Result<Mat4> world = NodeWorld(model, parent, armature, asset);
    if (!world.ok()) return world.status();
    armature_world = *world;
  }
  const Mat4 world_from_armature = armature_world;
  const Mat4 armature_from_world = world_from_armature.inverse();

  std::vector<Mat4> rest(hand.bones.size());
  for (size_t b = 0; b < hand.bones.size(); ++b) {
    Result<Mat4> world = NodeWorld(model, parent, node_of[b], asset);
    if (!world.ok()) return world.status();
    rest[b] = armature_from_world * *world;
  }
  HANDDB_RETURN_IF_ERROR(CheckRest(hand, rest, asset));

  // Each joint's target, the rig's posed bone in the armature's frame; its local transform is
  // taken relative to the parent's transform as written (a unit quaternion and a translation), so
  // what a reader composes is the target up to rounding, not up to errors summed down a finger.
  const std::vector<BonePose> posed = rig.PoseBones(joints);
  const Mat4 c = HandFromGltf();
  // A left hand: each joint at mirror * pose * diag(-1, 1, 1), a rotation, with the skin's data
  // mirrored to match (MirrorSkinData).
  Mat4 mirror = Mat4::Identity();
  Mat4 joint_flip = Mat4::Identity();
  if (options.left_hand) {
    Vec3d normal;
    if (options.cam_from_hand) {
      normal = (*options.cam_from_hand)[0];
    } else {
      const Vec3d& f = rig.forward_axis();
      const Vec3d& m = rig.palm_normal();
      normal = {f[1] * m[2] - f[2] * m[1], f[2] * m[0] - f[0] * m[2], f[0] * m[1] - f[1] * m[0]};
      if (!(std::hypot(normal[0], normal[1], normal[2]) > 1e-9)) {
        return Error(StatusCode::kSchemaViolation,
                     hand.path,
                     "forward_axis and palm_normal are parallel: no thumb side to mirror across");
      }
    }
    mirror = MirrorInArmature(normal, rig.look_at());
    joint_flip(0, 0) = -1;
    int skin = -1;
    for (size_t i = 0; i < model.skins.size() && skin < 0; ++i) {
      const std::vector<int>& skin_joints = model.skins[i].joints;
      if (std::find(skin_joints.begin(), skin_joints.end(), node_of[order[0]]) !=
          skin_joints.end()) {
        skin = static_cast<int>(i);
      }
    }
    HANDDB_RETURN_IF_ERROR(MirrorSkinData(skin, asset, &model));
  }
  std::vector<Mat4> written(hand.bones.size(), Mat4::Identity());
  for (const int b : order) {
    const int node = node_of[b];
    const Mat4 target =
        mirror * c.transpose() * ToMat4(posed[b].rotation, posed[b].head) * c * joint_flip;
    Mat4 parent_in_armature = Mat4::Identity();
    if (bone_parent[b] >= 0) {
      Reparent(node, node_of[bone_parent[b]], &parent, &model);
      parent_in_armature = written[bone_parent[b]];
    } else if (parent[node] != armature) {
      return Error(StatusCode::kSchemaViolation,
                   asset,
                   "root joint '" + hand.bones[b].name + "' is not under the armature of '" +
                       hand.bones[order[0]].name + "'");
    }
    SetRigidLocal(parent_in_armature.inverse() * target, &model.nodes[node]);
    written[b] = parent_in_armature * NodeLocal(model.nodes[node]);
  }
  // A joint parented under its own descendant would make a file no viewer can pose.
  for (const int node : node_of) {
    Result<Mat4> world = NodeWorld(model, parent, node, asset);
    if (!world.ok()) return world.status();
  }
  if (options.cam_from_hand) {
    AddCamera(*options.cam_from_hand, rig.look_at(), ortho_scale, armature, &model);
  }
  // Who made the file, and from what: the asset's own generator stays in the record.
  std::string made_by =
      std::string("handdb ") + HANDDB_VERSION + " (posed " + asset.filename().string();
  if (!model.asset.generator.empty()) made_by += ", made by " + model.asset.generator;
  model.asset.generator = made_by + ")";

  std::ostringstream bytes;
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&model, bytes, /*prettyPrint=*/false, /*writeBinary=*/true)) {
    return Error(StatusCode::kIoError, out, "tinygltf could not serialise the posed asset");
  }
  Status saved = WriteFileAtomic(out, bytes.str());
  // The writer names what failed, which may be a directory above the output.
  if (!saved.ok() && saved.message().find(out.string()) == std::string::npos) {
    return Error(saved.code(), out, saved.message());
  }
  return saved;
}

}  // namespace handdb
