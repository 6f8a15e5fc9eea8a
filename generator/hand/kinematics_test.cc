#include "generator/hand/kinematics.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/testing.h"

namespace handdb {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

fs::path HandPath() { return RepoRoot() / "configs/hands/webxr_generic_right.json"; }

HandRig ShippedRig() {
  auto model = LoadHandModel(HandPath());
  THROW_CHECK(model.ok());
  auto rig = HandRig::Create(*model);
  THROW_CHECK(rig.ok());
  return std::move(rig).value();
}

// Expected keypoints: blender_scripts/handdb_blender/kinematics.py `keypoints(model, joints)` on
// configs/hands/webxr_generic_right.json, run with /usr/bin/python3 and numpy, printed with 17
// significant digits. "fist" is the basic shape of configs/shapes/basic.json; "mixed" puts DOF i
// at min + (max - min) * ((7 i) mod 10) / 9, so every DOF, both signs and both ends of the
// limits are exercised.
struct Case {
  const char* name;
  JointVector joints;
  HandKeypoints3d keypoints;
};

const Case kCases[] = {
    {"fist",
     {0.78539800000000004,
      0.087265999999999996,
      0.78539800000000004,
      0.52359900000000004,
      1.48353,
      0,
      1.7453289999999999,
      1.0471980000000001,
      1.48353,
      0,
      1.7453289999999999,
      1.0471980000000001,
      1.48353,
      0,
      1.7453289999999999,
      1.0471980000000001,
      1.48353,
      0,
      1.7453289999999999,
      1.0471980000000001},
     {{
         {0.039126099999999997, -0.0091572000000000008, 0.055775499999999999},
         {0.019968400000000001, 0.018871300000000001, 0.019817000000000012},
         {0.0027365125016818592, 0.011086505250082548, -0.0066320424705358372},
         {-0.0070937368303452125, -0.014333889106277226, -0.026610524643026066},
         {-0.0098666860631428151, -0.028460199462820246, -0.030309066874706081},
         {0.031809599999999993, 0.0143935, -0.032773299999999991},
         {-0.013386064201354117, 0.010742624291337924, -0.033392182230020821},
         {-0.009154418903467354, 0.012749174459001597, -0.0095441171442476741},
         {0.001018620701954423, 0.01399093699507347, -0.004146549366934052},
         {0.036582899999999988, -0.0074313000000000001, -0.035871100000000003},
         {-0.010295700174423689, -0.0065496140538115737, -0.03556049641479473},
         {-0.0051745361966848182, -0.0024229259051210591, -0.0088074934845061292},
         {0.0053496172692098498, -0.0005610253891063649, -0.0029167354283932134},
         {0.032596800000000002, -0.026622400000000001, -0.028918300000000001},
         {-0.010037232727553969, -0.022166553195420713, -0.029307317979804889},
         {-0.0043377619690056664, -0.013888580948492098, -0.0047078784063126489},
         {0.0068512036889718936, -0.012560209301795848, -0.00075887076059925895},
         {0.025434900000000007, -0.044211300000000002, -0.018120400000000002},
         {-0.0081995213006013923, -0.036189808092799688, -0.018539024563397895},
         {-0.0039341484248473571, -0.030572858237145277, 0.00050859235182937335},
         {0.0071946557712184167, -0.03006923557109821, 0.0047174351845983703},
     }}},
    {"mixed",
     {-0.34906599999999999,
      0.69813200000000009,
      0.42663577777777772,
      -0.13574799999999998,
      1.3380854444444443,
      0.12605155555555558,
      0.42663600000000002,
      1.5707960000000001,
      0.87266433333333315,
      -0.087266333333333335,
      0,
      1.1829451111111111,
      0.4072432222222222,
      -0.1939251111111111,
      1.7065440000000001,
      0.79509422222222237,
      -0.058177888888888918,
      0.52359900000000004,
      1.2799079999999998,
      0.40724333333333346},
     {{
         {0.039126099999999997, -0.0091572000000000008, 0.055775499999999999},
         {0.019968400000000001, 0.018871300000000001, 0.019817000000000012},
         {-0.0054920014987075681, 0.039039161385981271, 0.018361604634368259},
         {-0.034347898690918303, 0.054318924650780198, 0.0096532210647615954},
         {-0.046084606764097633, 0.063429703174246954, 0.0092476849671745028},
         {0.031809599999999993, 0.0143935, -0.032773299999999991},
         {-0.012904524416831362, 0.012130838096109074, -0.039976593150351333},
         {-0.036117499658922497, 0.0099104291377812726, -0.033128903763885692},
         {-0.034461144604798641, 0.0096624480195374677, -0.021667601479454346},
         {0.036582899999999988, -0.0074313000000000001, -0.035871100000000003},
         {-0.0020700858056897642, -0.011982017488631978, -0.062019040903713803},
         {-0.024857195494344758, -0.015112279809054456, -0.077182410856113937},
         {-0.036081221308230133, -0.013365815299753322, -0.072721845738524526},
         {0.032596800000000002, -0.026622400000000001, -0.028918300000000001},
         {0.012565481670495475, -0.025661955329342141, -0.066806170357973094},
         {-0.0081494840001613139, -0.019973587279979031, -0.051164118707362302},
         {-0.010004931597287235, -0.017530694814512936, -0.039625411693840693},
         {0.025434900000000007, -0.044211300000000002, -0.018120400000000002},
         {0.019728348633602941, -0.067351871688165629, -0.04317520075739055},
         {-0.00012680387667063364, -0.067103566671252418, -0.047449149222818447},
         {-0.011300269953741976, -0.063027608826210474, -0.048047959206462057},
     }}},
};

TEST(HandRig, KeypointsEqualThePythonKinematics) {
  const HandRig rig = ShippedRig();
  for (const Case& c : kCases) {
    const HandKeypoints3d kp = rig.Keypoints3d(c.joints);
    for (int k = 0; k < kNumKeypoints; ++k) {
      for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(kp[k][a], c.keypoints[k][a], 1e-12) << c.name << " keypoint " << k;
      }
    }
  }
}

TEST(HandRig, ZeroPoseIsTheRestPose) {
  const HandRig rig = ShippedRig();
  const HandKeypoints3d kp = rig.Keypoints3d(JointVector{});
  for (const HandKeypoint& def : rig.model().keypoints) {
    ASSERT_FALSE(def.at_tail);
    for (const HandBone& bone : rig.model().bones) {
      if (bone.name != def.bone) continue;
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(kp[def.index][a], bone.head[a], 1e-12) << def.name;
    }
  }
}

TEST(HandRig, FlexionCurlsTowardsThePalm) {
  // Positive flexion curls towards the palm (docs/conventions.md), i.e. the index tip moves out
  // along palm_normal, the side the palm faces.
  const HandRig rig = ShippedRig();
  JointVector j{};
  const HandKeypoints3d rest = rig.Keypoints3d(j);
  j[4] = 1.0;  // index MCP flexion
  const HandKeypoints3d bent = rig.Keypoints3d(j);
  const Vec3d& n = rig.palm_normal();
  auto along = [&](const Vec3d& p) { return p[0] * n[0] + p[1] * n[1] + p[2] * n[2]; };
  EXPECT_GT(along(bent[8]) - along(rest[8]), 0.02);
  // Bones keep their lengths.
  auto dist = [](const Vec3d& a, const Vec3d& b) {
    return std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
  };
  EXPECT_NEAR(dist(bent[5], bent[6]), dist(rest[5], rest[6]), 1e-9);
  EXPECT_NEAR(dist(bent[7], bent[8]), dist(rest[7], rest[8]), 1e-9);
  // Other fingers do not move.
  for (int k : {0, 1, 4, 9, 12, 16, 20}) EXPECT_EQ(bent[k], rest[k]) << k;
}

TEST(HandRig, Limits) {
  const HandRig rig = ShippedRig();
  const JointLimits& limits = rig.limits();
  EXPECT_DOUBLE_EQ(limits.min[0], -0.349066);  // thumb CMC flexion
  EXPECT_DOUBLE_EQ(limits.max[1], 1.047198);   // thumb CMC abduction
  JointVector j{};
  EXPECT_TRUE(rig.OutsideLimits(j).empty());
  j[3] = limits.max[3] + 0.01;
  j[17] = limits.min[17] - 0.01;
  EXPECT_EQ(rig.OutsideLimits(j), (std::vector<int>{3, 17}));
  j[3] = limits.max[3] + 1e-12;
  j[17] = limits.min[17];
  EXPECT_TRUE(rig.OutsideLimits(j).empty());
  j[5] = std::nan("");
  EXPECT_EQ(rig.OutsideLimits(j), (std::vector<int>{5}));
}

class BrokenRig : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("handdb_rig_test_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    auto doc = ReadJsonFile(HandPath(), "");
    ASSERT_TRUE(doc.ok());
    doc_ = *doc;
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Writes doc_ (edited by the test) and returns HandRig::Create's status on it.
  Status Load() {
    const fs::path path = dir_ / "hand.json";
    THROW_CHECK(WriteJsonFileAtomic(path, doc_).ok());
    auto model = LoadHandModel(path);
    if (!model.ok()) return model.status();
    auto rig = HandRig::Create(*model);
    return rig.ok() ? Status::Ok() : rig.status();
  }
  void ExpectRefused(const std::string& needle) {
    const Status s = Load();
    EXPECT_FALSE(s.ok());
    EXPECT_NE(s.message().find((dir_ / "hand.json").string()), std::string::npos) << s.message();
    EXPECT_NE(s.message().find(needle), std::string::npos) << s.message();
  }

  fs::path dir_;
  json doc_;
};

TEST_F(BrokenRig, TheShippedModelLoads) { EXPECT_TRUE(Load().ok()) << Load().message(); }

TEST_F(BrokenRig, UnknownParent) {
  doc_["bones"][3]["parent"] = "no-such-bone";
  ExpectRefused("unknown parent 'no-such-bone'");
}

TEST_F(BrokenRig, Cycle) {
  doc_["bones"][1]["parent"] = doc_["bones"][2]["name"];
  ExpectRefused("cycle");
}

TEST_F(BrokenRig, DuplicateBone) {
  doc_["bones"][4]["name"] = doc_["bones"][3]["name"];
  ExpectRefused("appears twice");
}

TEST_F(BrokenRig, DofOnUnknownBone) {
  doc_["dofs"][6]["bone"] = "nowhere";
  ExpectRefused("unknown bone 'nowhere'");
}

TEST_F(BrokenRig, ZeroAxis) {
  doc_["dofs"][2]["axis"] = json::array({0.0, 0.0, 0.0});
  ExpectRefused("axis is zero");
}

TEST_F(BrokenRig, KeypointIndexTwice) {
  doc_["keypoints"][7]["index"] = 6;
  ExpectRefused("used twice");
}

TEST_F(BrokenRig, KeypointOnUnknownBone) {
  doc_["keypoints"][20]["bone"] = "elsewhere";
  ExpectRefused("unknown bone 'elsewhere'");
}

TEST_F(BrokenRig, TailWithoutLength) {
  doc_["keypoints"][8]["at"] = "tail";
  ExpectRefused("needs a length");
}

}  // namespace
}  // namespace handdb
