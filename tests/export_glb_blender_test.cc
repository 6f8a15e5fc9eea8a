// The posed hand (pose/export_gltf.h) as Blender opens it: Blender's own glTF importer
// (tests/blender/import_posed_glb.py) reads the exported .glb, and every pose bone's head must lie
// where HandRig puts it (a left hand: mirrored), the camera where the render camera stands. This is
// the check that the file means to a real importer what pose/export_gltf_test.cc computes from the
// glTF alone.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <nlohmann/json.hpp>
#include <random>

#include "base/repo_root.h"
#include "base/subprocess.h"
#include "base/testing.h"
#include "generator/hand/camera.h"
#include "generator/hand/rig_testing.h"
#include "generator/render/blender.h"
#include "pose/export_gltf.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// Blender imports in float32: the heads agree to ~3e-8 (two poses measured), so a joint turned
// the wrong way about any axis shows long before this.
constexpr double kTolerance = 1e-5;

using testing::ShippedRig;

// What Blender's importer made of `glb` (the script's JSON line).
json ImportWithBlender(const fs::path& blender, const fs::path& glb) {
  const std::vector<std::string> argv = {
      blender.string(),
      "-b",
      "--factory-startup",
      "-noaudio",
      "-P",
      (RepoRoot() / "tests/blender/import_posed_glb.py").string(),
      "--",
      glb.string()};
  RunOptions options;
  options.timeout_seconds = 300;
  auto run = RunSubprocess(argv, options);
  THROW_CHECK_MSG(run.ok(), run.status().ToString());
  THROW_CHECK_MSG(run->ok(), "blender failed: " + run->err + run->out);
  const std::string marker = "IMPORTED ";
  const size_t at = run->out.find(marker);
  THROW_CHECK_MSG(at != std::string::npos, "no IMPORTED line: " + run->out);
  const size_t end = run->out.find('\n', at);
  return json::parse(run->out.substr(at + marker.size(), end - at - marker.size()));
}

TEST(ExportGlbBlender, ImportedBonesAndCameraAreTheRigs) {
  auto blender = FindBlender("");
  if (!blender.ok()) GTEST_SKIP() << "Blender not installed";
  const HandRig rig = ShippedRig();
  const fs::path dir = testing::TempDir("export_glb_blender");

  for (uint32_t seed : {1u, 2u}) {
    std::mt19937 rng(seed);
    JointVector joints;
    for (int i = 0; i < kNumJointAngles; ++i) {
      joints[i] =
          std::uniform_real_distribution<double>(rig.limits().min[i], rig.limits().max[i])(rng);
    }
    const Vec3d direction{0.3, -0.8, 0.5 * seed};
    const double roll = 0.4 * seed;
    auto cam_from_hand = CamFromHand(rig, direction, roll);
    ASSERT_TRUE(cam_from_hand.ok());
    PosedHandGlbOptions options;
    options.cam_from_hand = *cam_from_hand;
    options.left_hand = seed == 2;
    const fs::path glb = dir / ("pose" + std::to_string(seed) + ".glb");
    ASSERT_TRUE(WritePosedHandGlb(glb, rig, joints, options).ok());

    const json imported = ImportWithBlender(*blender, glb);
    std::vector<BonePose> posed = rig.PoseBones(joints);
    if (options.left_hand) {
      // Mirrored across the plane through look_at normal to the image x axis.
      const Vec3d& n = (*cam_from_hand)[0];
      for (BonePose& bone : posed) {
        double d = 0;
        for (int r = 0; r < 3; ++r) d += n[r] * (bone.head[r] - rig.look_at()[r]);
        for (int r = 0; r < 3; ++r) bone.head[r] -= 2 * d * n[r];
      }
    }
    ASSERT_EQ(imported["bones"].size(), rig.model().bones.size());
    double worst = 0;
    for (size_t b = 0; b < posed.size(); ++b) {
      const std::string& name = rig.model().bones[b].name;
      ASSERT_TRUE(imported["bones"].contains(name)) << name;
      const json& head = imported["bones"][name];
      for (int r = 0; r < 3; ++r) {
        EXPECT_NEAR(head[r].get<double>(), posed[b].head[r], kTolerance)
            << name << " seed " << seed;
        worst = std::max(worst, std::abs(head[r].get<double>() - posed[b].head[r]));
      }
    }
    std::cout << "seed " << seed << ": largest head difference " << worst << "\n";
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) {
        EXPECT_NEAR(imported["armature_world"][r][c].get<double>(), r == c ? 1.0 : 0.0, 1e-6);
      }
    }

    // Blender's camera looks along its -z with +y up, placed as blender_scripts' render camera:
    // axes (x, -y, -z) of cam_from_hand's rows, 1.0 from look_at towards the view direction.
    ASSERT_EQ(imported["cameras"].size(), 1u);
    const json& camera = imported["cameras"][0];
    EXPECT_EQ(camera["type"], "ORTHO");
    EXPECT_NEAR(camera["ortho_scale"].get<double>(), rig.model().ortho_scale, 1e-6);
    const double n = std::sqrt(direction[0] * direction[0] + direction[1] * direction[1] +
                               direction[2] * direction[2]);
    const double flip[3] = {1, -1, -1};
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(camera["world"][r][c].get<double>(), flip[c] * (*cam_from_hand)[c][r], 1e-5);
      }
      EXPECT_NEAR(camera["world"][r][3].get<double>(), rig.look_at()[r] + direction[r] / n, 1e-5);
    }
  }
}

}  // namespace
}  // namespace handdb
