#include "pose/export_gltf.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <random>

#include "base/repo_root.h"
#include "base/testing.h"
#include "generator/hand/camera.h"
#include "generator/hand/rig_testing.h"
#include "generator/plan/plan.h"
#include "pose/tiny_gltf_config.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using Mat4 = Eigen::Matrix4d;

constexpr double kTolerance = 1e-5;

using testing::ShippedRig;

fs::path ShippedAsset(const HandRig& rig) { return ResolvePlanPath(rig.model().asset_path); }

tinygltf::Model ReadGlb(const fs::path& path) {
  tinygltf::TinyGLTF loader;
  tinygltf::Model model;
  std::string err, warn;
  const bool ok = loader.LoadBinaryFromFile(&model, &err, &warn, path.string());
  THROW_CHECK_MSG(ok, path.string() + ": " + err);
  return model;
}

// glTF's node transforms composed from the scene roots down, written independently of the export.
Mat4 Local(const tinygltf::Node& node) {
  Mat4 m = Mat4::Identity();
  if (node.matrix.size() == 16) {
    for (int i = 0; i < 16; ++i) m(i % 4, i / 4) = node.matrix[i];
    return m;
  }
  Eigen::Affine3d t = Eigen::Affine3d::Identity();
  if (node.translation.size() == 3) t.translate(Eigen::Vector3d(node.translation.data()));
  if (node.rotation.size() == 4) {
    t.rotate(
        Eigen::Quaterniond(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]));
  }
  if (node.scale.size() == 3) t.scale(Eigen::Vector3d(node.scale.data()));
  return t.matrix();
}

std::vector<Mat4> Worlds(const tinygltf::Model& model) {
  std::vector<Mat4> world(model.nodes.size(), Mat4::Identity());
  std::vector<bool> seen(model.nodes.size(), false);
  std::vector<std::pair<int, Mat4>> stack;
  for (const int root : model.scenes.at(std::max(model.defaultScene, 0)).nodes) {
    stack.emplace_back(root, Mat4::Identity());
  }
  while (!stack.empty()) {
    auto [node, parent_world] = stack.back();
    stack.pop_back();
    THROW_CHECK(!seen[node]);
    seen[node] = true;
    world[node] = parent_world * Local(model.nodes[node]);
    for (const int child : model.nodes[node].children) stack.emplace_back(child, world[node]);
  }
  return world;
}

int NodeNamed(const tinygltf::Model& model, const std::string& name) {
  for (size_t i = 0; i < model.nodes.size(); ++i) {
    if (model.nodes[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

// The hand frame from glTF's axes (docs/hand_model.md: glTF +Y up is the hand frame's +Z).
Mat4 GltfToHand(const Mat4& world_gltf) {
  Mat4 c = Mat4::Zero();
  c(0, 0) = 1;
  c(1, 2) = -1;
  c(2, 1) = 1;
  c(3, 3) = 1;
  return c * world_gltf * c.transpose();
}

double MaxDiff(const Mat4& transform, const BonePose& bone) {
  double d = 0;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) d = std::max(d, std::abs(transform(r, c) - bone.rotation[r][c]));
    d = std::max(d, std::abs(transform(r, 3) - bone.head[r]));
  }
  return d;
}

Mat4 ToMat4ForTest(const BonePose& bone) {
  Mat4 m = Mat4::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = bone.rotation[r][c];
    m(r, 3) = bone.head[r];
  }
  return m;
}

JointVector RandomJoints(const HandRig& rig, uint32_t seed) {
  std::mt19937 rng(seed);
  JointVector joints;
  for (int i = 0; i < kNumJointAngles; ++i) {
    joints[i] =
        std::uniform_real_distribution<double>(rig.limits().min[i], rig.limits().max[i])(rng);
  }
  return joints;
}

// Every joint node's world transform is the rig's posed bone, in the hand frame.
void ExpectJointsMatchRig(const HandRig& rig,
                          const JointVector& joints,
                          const tinygltf::Model& model) {
  const std::vector<Mat4> world = Worlds(model);
  const std::vector<BonePose> posed = rig.PoseBones(joints);
  for (size_t b = 0; b < rig.model().bones.size(); ++b) {
    const int node = NodeNamed(model, rig.model().bones[b].name);
    ASSERT_GE(node, 0) << rig.model().bones[b].name;
    EXPECT_LE(MaxDiff(GltfToHand(world[node]), posed[b]), kTolerance) << rig.model().bones[b].name;
  }
}

TEST(PosedHandGlbOptions, Check) {
  PosedHandGlbOptions options;
  EXPECT_TRUE(options.Check());
  options.cam_from_hand = Mat3d{{{1, 0, 0}, {0, 0, 1}, {0, -1, 0}}};
  options.ortho_scale = 0.3;
  EXPECT_TRUE(options.Check());
  options.ortho_scale = -1;
  EXPECT_FALSE(options.Check());
  options.ortho_scale = NAN;
  EXPECT_FALSE(options.Check());
  options.ortho_scale = 0;
  options.cam_from_hand = Mat3d{{{1, 0, 0}, {0, 1, 0}, {0, 0, -1}}};  // a reflection
  EXPECT_FALSE(options.Check());
  options.cam_from_hand = Mat3d{{{2, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
  EXPECT_FALSE(options.Check());
}

TEST(WritePosedHandGlb, JointWorldTransformsAreTheRigsPosedBones) {
  const HandRig rig = ShippedRig();
  const fs::path dir = testing::TempDir("export_gltf_joints");
  for (uint32_t seed = 1; seed <= 5; ++seed) {
    const JointVector joints = RandomJoints(rig, seed);
    const fs::path out = dir / "pose.glb";
    ASSERT_TRUE(WritePosedHandGlb(out, rig, joints).ok());
    const tinygltf::Model model = ReadGlb(out);
    ExpectJointsMatchRig(rig, joints, model);

    // The 21 keypoints from the exported nodes alone.
    const std::vector<Mat4> world = Worlds(model);
    const HandKeypoints3d expected = rig.Keypoints3d(joints);
    for (const HandKeypoint& kp : rig.model().keypoints) {
      const Mat4 bone = GltfToHand(world[NodeNamed(model, kp.bone)]);
      for (int r = 0; r < 3; ++r) {
        const double at = bone(r, 3) + (kp.at_tail ? kp.length * bone(r, 1) : 0.0);
        EXPECT_NEAR(at, expected[kp.index][r], kTolerance) << kp.name;
      }
    }
  }
}

TEST(WritePosedHandGlb, ParentsJointsAsTheRigAndKeepsMeshAndSkin) {
  const HandRig rig = ShippedRig();
  const fs::path out = testing::TempDir("export_gltf_parents") / "pose.glb";
  ASSERT_TRUE(WritePosedHandGlb(out, rig, RandomJoints(rig, 7)).ok());
  const tinygltf::Model posed = ReadGlb(out);
  const tinygltf::Model asset = ReadGlb(ShippedAsset(rig));

  std::map<int, int> parent;
  for (size_t i = 0; i < posed.nodes.size(); ++i) {
    for (const int child : posed.nodes[i].children) parent[child] = static_cast<int>(i);
  }
  for (const HandBone& bone : rig.model().bones) {
    if (bone.parent.empty()) continue;
    EXPECT_EQ(parent.at(NodeNamed(posed, bone.name)), NodeNamed(posed, bone.parent)) << bone.name;
  }
  ASSERT_EQ(posed.buffers.size(), asset.buffers.size());
  for (size_t i = 0; i < asset.buffers.size(); ++i) {
    EXPECT_TRUE(posed.buffers[i].data == asset.buffers[i].data);
  }
  ASSERT_EQ(posed.skins.size(), 1u);
  EXPECT_EQ(posed.skins[0].joints, asset.skins[0].joints);
  EXPECT_EQ(posed.skins[0].inverseBindMatrices, asset.skins[0].inverseBindMatrices);
  EXPECT_EQ(posed.nodes.size(), asset.nodes.size());
  EXPECT_TRUE(posed.cameras.empty());
}

TEST(WritePosedHandGlb, ZeroPoseIsTheRestPose) {
  const HandRig rig = ShippedRig();
  const fs::path out = testing::TempDir("export_gltf_rest") / "rest.glb";
  const JointVector zero{};
  ASSERT_TRUE(WritePosedHandGlb(out, rig, zero).ok());
  const tinygltf::Model posed = ReadGlb(out);
  ExpectJointsMatchRig(rig, zero, posed);

  // Every joint where the asset has it, so joint world x inverse bind matrix is the identity and
  // the skinned mesh is the asset's own.
  const tinygltf::Model asset = ReadGlb(ShippedAsset(rig));
  const std::vector<Mat4> posed_world = Worlds(posed);
  const std::vector<Mat4> asset_world = Worlds(asset);
  const tinygltf::Accessor& ibm = posed.accessors[posed.skins[0].inverseBindMatrices];
  const tinygltf::BufferView& view = posed.bufferViews[ibm.bufferView];
  const auto* floats = reinterpret_cast<const float*>(posed.buffers[view.buffer].data.data() +
                                                      view.byteOffset + ibm.byteOffset);
  for (size_t j = 0; j < posed.skins[0].joints.size(); ++j) {
    const int node = posed.skins[0].joints[j];
    EXPECT_LE((posed_world[node] - asset_world[node]).cwiseAbs().maxCoeff(), kTolerance)
        << posed.nodes[node].name;
    Mat4 inverse_bind;
    for (int i = 0; i < 16; ++i) inverse_bind(i % 4, i / 4) = floats[16 * j + i];
    EXPECT_LE((posed_world[node] * inverse_bind - Mat4::Identity()).cwiseAbs().maxCoeff(), 1e-5)
        << posed.nodes[node].name;
  }
}

// The camera node sees the keypoints where the render camera puts them.
TEST(WritePosedHandGlb, CameraSeesTheHandAsTheRenderCamera) {
  const HandRig rig = ShippedRig();
  const JointVector joints = RandomJoints(rig, 11);
  auto cam_from_hand = CamFromHand(rig, {0.3, -0.8, 0.5}, 0.7);
  ASSERT_TRUE(cam_from_hand.ok());
  PosedHandGlbOptions options;
  options.cam_from_hand = *cam_from_hand;
  const fs::path out = testing::TempDir("export_gltf_camera") / "pose.glb";
  ASSERT_TRUE(WritePosedHandGlb(out, rig, joints, options).ok());
  const tinygltf::Model model = ReadGlb(out);

  ASSERT_EQ(model.cameras.size(), 1u);
  const tinygltf::Camera& camera = model.cameras[0];
  EXPECT_EQ(camera.type, "orthographic");
  EXPECT_DOUBLE_EQ(camera.orthographic.xmag, rig.model().ortho_scale / 2);
  EXPECT_DOUBLE_EQ(camera.orthographic.ymag, rig.model().ortho_scale / 2);
  int camera_node = -1;
  for (size_t i = 0; i < model.nodes.size(); ++i) {
    if (model.nodes[i].camera == 0) camera_node = static_cast<int>(i);
  }
  ASSERT_GE(camera_node, 0);
  const std::vector<Mat4> world = Worlds(model);
  const Mat4 camera_from_world = world[camera_node].inverse();

  RenderSettings render;
  render.resolution = 256;
  render.ortho_scale = rig.model().ortho_scale;
  const double px_per_unit = render.resolution / render.ortho_scale;
  const HandKeypoints3d points = rig.Keypoints3d(joints);
  for (const HandKeypoint& kp : rig.model().keypoints) {
    const Mat4 bone = GltfToHand(world[NodeNamed(model, kp.bone)]);
    Eigen::Vector4d in_hand = bone.col(3);
    if (kp.at_tail) in_hand.head<3>() += kp.length * bone.block<3, 1>(0, 1);
    const Eigen::Vector4d p(in_hand.x(), in_hand.z(), -in_hand.y(), 1.0);  // glTF's axes
    const Eigen::Vector4d in_camera = camera_from_world * p;
    const Vec3d px = ProjectToRenderPx(points[kp.index], rig.look_at(), *cam_from_hand, render);
    // glTF's camera: +x right, +y up, looking along -z.
    EXPECT_NEAR(render.resolution / 2.0 + in_camera.x() * px_per_unit, px[0], 1e-3) << kp.name;
    EXPECT_NEAR(render.resolution / 2.0 - in_camera.y() * px_per_unit, px[1], 1e-3) << kp.name;
    EXPECT_NEAR((-in_camera.z() - 1.0) * px_per_unit, px[2], 1e-3) << kp.name;
  }
}

// The reflection across the plane through `point` normal to `normal`, in the hand frame.
Mat4 Mirror(const Vec3d& normal, const Vec3d& point) {
  const Eigen::Vector3d n = Eigen::Vector3d(normal.data()).normalized();
  Mat4 m = Mat4::Identity();
  m.topLeftCorner<3, 3>() -= 2 * n * n.transpose();
  m.col(3).head<3>() = 2 * n.dot(Eigen::Vector3d(point.data())) * n;
  return m;
}

// Element i of a float accessor.
const float* Floats(const tinygltf::Model& model, int accessor_index, size_t i) {
  const tinygltf::Accessor& accessor = model.accessors.at(accessor_index);
  THROW_CHECK(accessor.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT);
  const tinygltf::BufferView& view = model.bufferViews.at(accessor.bufferView);
  const size_t size = 4 * tinygltf::GetNumComponentsInType(accessor.type);
  const size_t stride = view.byteStride > 0 ? view.byteStride : size;
  return reinterpret_cast<const float*>(model.buffers.at(view.buffer).data.data() +
                                        view.byteOffset + accessor.byteOffset + i * stride);
}

uint32_t Index(const tinygltf::Model& model, int accessor_index, size_t i) {
  const tinygltf::Accessor& accessor = model.accessors.at(accessor_index);
  const tinygltf::BufferView& view = model.bufferViews.at(accessor.bufferView);
  const int size = tinygltf::GetComponentSizeInBytes(accessor.componentType);
  const int count = tinygltf::GetNumComponentsInType(accessor.type);
  const unsigned char* p =
      model.buffers.at(view.buffer).data.data() + view.byteOffset + accessor.byteOffset +
      (i / count) * (view.byteStride > 0 ? view.byteStride : size * count) + (i % count) * size;
  return size == 1   ? *p
         : size == 2 ? *reinterpret_cast<const uint16_t*>(p)
                     : *reinterpret_cast<const uint32_t*>(p);
}

// The mesh as a viewer draws it: glTF skinning (sum of weight x joint world x inverse bind) of
// every vertex and normal, and the triangles; positions and normals in the hand frame.
struct SkinnedMesh {
  std::vector<Eigen::Vector3d> positions, normals;
  std::vector<uint32_t> triangles;
};

SkinnedMesh Skin(const tinygltf::Model& model) {
  const std::vector<Mat4> world = Worlds(model);
  const tinygltf::Skin& skin = model.skins.at(0);
  const tinygltf::Primitive& primitive = model.meshes.at(0).primitives.at(0);
  SkinnedMesh mesh;
  const int positions = primitive.attributes.at("POSITION");
  const int normals = primitive.attributes.at("NORMAL");
  const int joints = primitive.attributes.at("JOINTS_0");
  const int weights = primitive.attributes.at("WEIGHTS_0");
  for (size_t v = 0; v < model.accessors[positions].count; ++v) {
    Mat4 blend = Mat4::Zero();
    for (int k = 0; k < 4; ++k) {
      const uint32_t j = Index(model, joints, 4 * v + k);
      Mat4 inverse_bind;
      const float* m = Floats(model, skin.inverseBindMatrices, j);
      for (int i = 0; i < 16; ++i) inverse_bind(i % 4, i / 4) = m[i];
      blend += Floats(model, weights, v)[k] * world[skin.joints[j]] * inverse_bind;
    }
    const float* p = Floats(model, positions, v);
    const float* n = Floats(model, normals, v);
    // GltfToHand(T) = C T C^T, so C T x = GltfToHand(T) (C x), with C x = (x, -z, y).
    const Mat4 hand = GltfToHand(blend);
    const Eigen::Vector4d in_hand = hand * Eigen::Vector4d(p[0], -p[2], p[1], 1.0);
    mesh.positions.push_back(in_hand.head<3>());
    mesh.normals.push_back(
        (hand.topLeftCorner<3, 3>() * Eigen::Vector3d(n[0], -n[2], n[1])).normalized());
  }
  for (size_t i = 0; i < model.accessors.at(primitive.indices).count; ++i) {
    mesh.triangles.push_back(Index(model, primitive.indices, i));
  }
  return mesh;
}

// The fraction of triangles whose winding (counter-clockwise from the front) agrees with their
// vertices' normals: the outside is out.
double OutwardFraction(const SkinnedMesh& mesh) {
  int outward = 0;
  for (size_t t = 0; t < mesh.triangles.size(); t += 3) {
    const Eigen::Vector3d& a = mesh.positions[mesh.triangles[t]];
    const Eigen::Vector3d& b = mesh.positions[mesh.triangles[t + 1]];
    const Eigen::Vector3d& c = mesh.positions[mesh.triangles[t + 2]];
    const Eigen::Vector3d n = mesh.normals[mesh.triangles[t]] +
                              mesh.normals[mesh.triangles[t + 1]] +
                              mesh.normals[mesh.triangles[t + 2]];
    if ((b - a).cross(c - a).dot(n) > 0) ++outward;
  }
  return outward / (mesh.triangles.size() / 3.0);
}

TEST(WritePosedHandGlb, LeftHandIsTheMirrorImageAcrossTheThumbSide) {
  const HandRig rig = ShippedRig();
  const JointVector joints = RandomJoints(rig, 13);
  const fs::path dir = testing::TempDir("export_gltf_left");
  PosedHandGlbOptions options;
  ASSERT_TRUE(WritePosedHandGlb(dir / "right.glb", rig, joints, options).ok());
  options.left_hand = true;
  ASSERT_TRUE(WritePosedHandGlb(dir / "left.glb", rig, joints, options).ok());
  const tinygltf::Model right = ReadGlb(dir / "right.glb");
  const tinygltf::Model left = ReadGlb(dir / "left.glb");

  // Every joint: the mirrored bone with its x axis turned, a rotation again.
  const std::vector<Mat4> world = Worlds(left);
  const std::vector<BonePose> posed = rig.PoseBones(joints);
  // The hand frame's +y points to the thumb (docs/hand_model.md).
  const Mat4 mirror = Mirror({0, 1, 0}, rig.look_at());
  const Mat4 flip_x = Eigen::Vector4d(-1, 1, 1, 1).asDiagonal();
  for (size_t b = 0; b < posed.size(); ++b) {
    const Mat4 got = GltfToHand(world[NodeNamed(left, rig.model().bones[b].name)]);
    EXPECT_LE((got - mirror * ToMat4ForTest(posed[b]) * flip_x).cwiseAbs().maxCoeff(), kTolerance)
        << rig.model().bones[b].name;
    const double determinant = got.topLeftCorner<3, 3>().determinant();
    EXPECT_NEAR(determinant, 1.0, 1e-6) << rig.model().bones[b].name;
  }

  // The skinned mesh: every vertex and normal the mirror of the right hand's, the faces still
  // wound with their outside out.
  const SkinnedMesh right_mesh = Skin(right);
  const SkinnedMesh left_mesh = Skin(left);
  ASSERT_EQ(left_mesh.positions.size(), right_mesh.positions.size());
  double worst = 0;
  for (size_t v = 0; v < right_mesh.positions.size(); ++v) {
    const Eigen::Vector3d mirrored = (mirror * right_mesh.positions[v].homogeneous()).head<3>();
    worst = std::max(worst, (left_mesh.positions[v] - mirrored).cwiseAbs().maxCoeff());
    worst = std::max(worst,
                     (left_mesh.normals[v] - mirror.topLeftCorner<3, 3>() * right_mesh.normals[v])
                         .cwiseAbs()
                         .maxCoeff());
  }
  EXPECT_LE(worst, kTolerance);
  const double right_outward = OutwardFraction(right_mesh);
  EXPECT_GT(right_outward, 0.9);
  EXPECT_NEAR(OutwardFraction(left_mesh), right_outward, 1e-9);
}

TEST(WritePosedHandGlb, LeftHandThroughTheCameraIsTheMirroredImage) {
  const HandRig rig = ShippedRig();
  const JointVector joints = RandomJoints(rig, 17);
  auto cam_from_hand = CamFromHand(rig, {-0.2, 0.4, 0.9}, 2.1);
  ASSERT_TRUE(cam_from_hand.ok());
  PosedHandGlbOptions options;
  options.cam_from_hand = *cam_from_hand;
  options.left_hand = true;
  const fs::path out = testing::TempDir("export_gltf_left_camera") / "left.glb";
  ASSERT_TRUE(WritePosedHandGlb(out, rig, joints, options).ok());
  const tinygltf::Model model = ReadGlb(out);
  const std::vector<Mat4> world = Worlds(model);
  int camera_node = -1;
  for (size_t i = 0; i < model.nodes.size(); ++i) {
    if (model.nodes[i].camera == 0) camera_node = static_cast<int>(i);
  }
  ASSERT_GE(camera_node, 0);
  // The camera itself is not mirrored: a rotation.
  const double camera_determinant = world[camera_node].topLeftCorner<3, 3>().determinant();
  EXPECT_NEAR(camera_determinant, 1.0, 1e-9);
  const Mat4 camera_from_world = world[camera_node].inverse();

  RenderSettings render;
  render.resolution = 256;
  render.ortho_scale = rig.model().ortho_scale;
  const double px_per_unit = render.resolution / render.ortho_scale;
  const HandKeypoints3d points = rig.Keypoints3d(joints);
  for (const HandKeypoint& kp : rig.model().keypoints) {
    const Eigen::Vector4d in_camera = camera_from_world * world[NodeNamed(model, kp.bone)].col(3);
    const Vec3d px = ProjectToRenderPx(points[kp.index], rig.look_at(), *cam_from_hand, render);
    // The right hand's image mirrored left to right about the image centre.
    EXPECT_NEAR(
        render.resolution / 2.0 + in_camera.x() * px_per_unit, render.resolution - px[0], 1e-3)
        << kp.name;
    EXPECT_NEAR(render.resolution / 2.0 - in_camera.y() * px_per_unit, px[1], 1e-3) << kp.name;
    EXPECT_NEAR((-in_camera.z() - 1.0) * px_per_unit, px[2], 1e-3) << kp.name;
  }
}

TEST(WritePosedHandGlb, ErrorsNameTheFileAndLeaveNoOutput) {
  const HandRig rig = ShippedRig();
  const fs::path dir = testing::TempDir("export_gltf_errors");
  const JointVector joints = RandomJoints(rig, 3);

  // An output under a regular file, and an output that is a directory.
  testing::WriteBytes(dir / "file", {'x'});
  const fs::path under_file = dir / "file" / "pose.glb";
  Status s = WritePosedHandGlb(under_file, rig, joints);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(under_file.string()), std::string::npos) << s.ToString();
  EXPECT_EQ(s.message().find('\n'), std::string::npos) << s.ToString();
  fs::create_directory(dir / "a_directory");
  s = WritePosedHandGlb(dir / "a_directory", rig, joints);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("a_directory"), std::string::npos) << s.ToString();
  EXPECT_EQ(s.message().find('\n'), std::string::npos) << s.ToString();
  EXPECT_TRUE(fs::is_empty(dir / "a_directory"));

  // A missing asset, a file that is not a glb, a glb of another hand: the old output stays.
  const fs::path out = dir / "pose.glb";
  testing::WriteBytes(out, {'o', 'l', 'd'});
  PosedHandGlbOptions options;
  options.asset = dir / "no_such.glb";
  s = WritePosedHandGlb(out, rig, joints, options);
  EXPECT_EQ(s.code(), StatusCode::kNotFound) << s.ToString();
  EXPECT_NE(s.message().find("no_such.glb"), std::string::npos) << s.ToString();

  options.asset = dir / "text.glb";
  testing::WriteBytes(options.asset, {'n', 'o', 't', ' ', 'a', ' ', 'g', 'l', 'b', '!', '!', '!'});
  s = WritePosedHandGlb(out, rig, joints, options);
  EXPECT_EQ(s.code(), StatusCode::kBadMagic) << s.ToString();
  EXPECT_NE(s.message().find("text.glb"), std::string::npos) << s.ToString();

  // The asset with its index tip's rest moved by 1 mm.
  tinygltf::Model moved = ReadGlb(ShippedAsset(rig));
  moved.nodes[NodeNamed(moved, "index-finger-tip")].translation[0] += 1e-3;
  options.asset = dir / "moved.glb";
  std::ostringstream bytes;
  tinygltf::TinyGLTF writer;
  ASSERT_TRUE(writer.WriteGltfSceneToStream(&moved, bytes, false, true));
  const std::string moved_bytes = bytes.str();
  testing::WriteBytes(options.asset, std::vector<uint8_t>(moved_bytes.begin(), moved_bytes.end()));
  s = WritePosedHandGlb(out, rig, joints, options);
  EXPECT_EQ(s.code(), StatusCode::kSchemaViolation) << s.ToString();
  EXPECT_NE(s.message().find("moved.glb"), std::string::npos) << s.ToString();
  EXPECT_NE(s.message().find("index-finger-tip"), std::string::npos) << s.ToString();

  JointVector bad = joints;
  bad[4] = NAN;
  s = WritePosedHandGlb(out, rig, bad);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.ToString();
  EXPECT_NE(s.message().find("index_mcp_flexion"), std::string::npos) << s.ToString();

  EXPECT_EQ(testing::ReadBytes(out), (std::vector<uint8_t>{'o', 'l', 'd'}));
  size_t entries = 0;
  for ([[maybe_unused]] const auto& entry : fs::directory_iterator(dir)) ++entries;
  EXPECT_EQ(entries, 5u);  // file, a_directory, pose.glb, text.glb, moved.glb: nothing half-written
}

}  // namespace
}  // namespace handdb
