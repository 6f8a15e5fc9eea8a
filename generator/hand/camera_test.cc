#include "generator/hand/camera.h"

#include <gtest/gtest.h>

#include <cmath>

#include "base/testing.h"
#include "format/roll.h"
#include "generator/hand/rig_testing.h"

namespace handdb {
namespace {

using nlohmann::json;

using testing::ShippedRig;

const JointVector kFist = {0.785398, 0.087266, 0.785398, 0.523599, 1.48353,  0.0,     1.745329,
                           1.047198, 1.48353,  0.0,      1.745329, 1.047198, 1.48353, 0.0,
                           1.745329, 1.047198, 1.48353,  0.0,      1.745329, 1.047198};

// Expected values: blender_scripts/handdb_blender/camera.py (cam_from_hand_rotation, project at
// resolution 256, ortho_scale 0.3) on the fist keypoints of kinematics.py, for the direction
// normalised by camera._unit; run with /usr/bin/python3 and numpy, 17 significant digits. The
// third case is near the pole (|d . forward_axis| > 0.99: image up from -palm_normal).
struct Case {
  Vec3d direction;
  double roll;
  Mat3d cam_from_hand;
  std::array<std::pair<int, Vec3d>, 5> px;
};

const Case kCases[] = {
    {{0.30304576336566319, -0.5050762722761053, 0.80812203564176865},
     0.0,
     {{{-0.85749292571254421, -0.51449575542752657, 0},
       {-0.4157753572051423, 0.69295892867523712, 0.58901508937395153},
       {-0.30304576336566319, 0.5050762722761053, -0.80812203564176865}}},
     {{{0, {120.35170823948008, 154.5439059625364, -68.99606296821662}},
       {4, {164.67578610677305, 117.24359530353337, -5.282437658679104}},
       {8, {138.07311682383516, 151.63392645698437, -7.8426008569342311}},
       {12, {141.29284927148933, 142.11050890669486, -16.082541823023522}},
       {20, {152.89796195480324, 127.84409177930549, -34.542163709101651}}}}},
    {{0.30304576336566319, -0.5050762722761053, 0.80812203564176865},
     1.1,
     {{{-0.018413406779685559, -0.85094337660750707, -0.52493458283730976},
       {-0.95279809600821952, -0.14419892160306902, 0.2671749600011642},
       {-0.30304576336566319, 0.5050762722761053, -0.80812203564176865}}},
     {{{0, {100.8746401633059, 133.2239988832192, -68.99606296821662}},
       {4, {154.22218136155678, 155.80666706359395, -5.282437658679104}},
       {8, {111.50639751634321, 147.69749322710601, -7.8426008569342311}},
       {12, {121.45419548038348, 146.24715721835642, -16.082541823023522}},
       {20, {139.43256552787736, 150.11852758044486, -34.542163709101651}}}}},
    {{-0.050027422543390578, 0.020010969017356231, -0.99854735396607586},
     0.4,
     {{{0.38893073000907563, 0.92126643280059695, -0.0010232543531481404},
       {-0.91990768245964383, 0.38841694210455102, 0.053871465896866949},
       {0.050027422543390578, -0.020010969017356231, 0.99854735396607586}}},
     {{{0, {122.78375082084128, 111.86821500421432, 72.360820013780909}},
       {4, {91.423819856884009, 139.97166157586668, -2.7531875005185773}},
       {8, {128.38652189378041, 146.69991882377397, 19.279527673982432}},
       {12, {118.38286516262858, 138.53343872465197, 20.760824670604229}},
       {20, {95.790743085167023, 127.65558067966379, 27.848501484075459}}}}},
    {{0, 0, 1},
     2.5,
     {{{0.59847214410395655, 0.8011436155469337, 0},
       {0.8011436155469337, -0.59847214410395655, 0},
       {0, 0, -1}}},
     {{{0, {127.80365036332708, 148.65613222595903, -71.39200000000001}},
       {4, {89.586867428816277, 125.02054798174176, 2.0668303997491906}},
       {8, {124.16735581272263, 110.78257154442738, -20.258517873549607}},
       {12, {116.43083873022444, 121.17505741347706, -21.307959101104458}},
       {20, {97.200024824928761, 137.506135926637, -27.822451357523938}}}}},
};

TEST(HandCamera, EqualsThePythonCamera) {
  const HandRig rig = ShippedRig();
  const RenderSettings params{256, 0.3};
  const HandKeypoints3d points = rig.Keypoints3d(kFist);
  for (const Case& c : kCases) {
    auto r = CamFromHand(rig, c.direction, c.roll);
    ASSERT_TRUE(r.ok()) << r.status().message();
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) EXPECT_NEAR((*r)[i][j], c.cam_from_hand[i][j], 1e-14);
    }
    for (const auto& [k, expected] : c.px) {
      const Vec3d px = ProjectToRenderPx(points[k], rig.look_at(), *r, params);
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(px[a], expected[a], 1e-9) << "keypoint " << k;
    }
  }
}

TEST(HandCamera, ViewKeypointsFollowTheLabel) {
  const HandRig rig = ShippedRig();
  const RenderSettings params{256, 0.3};
  const Case& c = kCases[1];
  ViewLabel label;
  for (int i = 0; i < kNumJointAngles; ++i) label.joint_angles[i] = static_cast<float>(kFist[i]);
  for (int i = 0; i < 3; ++i) label.view_direction[i] = static_cast<float>(c.direction[i]);
  label.camera_roll = static_cast<float>(c.roll);
  label.scale = 1.5f;
  label.source_centre_px = {130.25f, 140.75f};
  auto px = ViewKeypointsPx(rig, label, params);
  ASSERT_TRUE(px.ok()) << px.status().message();
  // float joint angles and direction move the keypoints by far less than a thousandth of a px.
  for (const auto& [k, expected] : c.px) {
    for (int a = 0; a < 3; ++a) EXPECT_NEAR((*px)[k][a], expected[a], 1e-3) << k;
  }
  auto norm = ViewKeypointsNormalised(rig, label, params);
  ASSERT_TRUE(norm.ok());
  for (int k = 0; k < kNumKeypoints; ++k) {
    EXPECT_NEAR((*norm)[k][0], ((*px)[k][0] - 130.25) * 1.5, 1e-4);
    EXPECT_NEAR((*norm)[k][1], ((*px)[k][1] - 140.75) * 1.5, 1e-4);
    EXPECT_NEAR((*norm)[k][2], (*px)[k][2] * 1.5, 1e-4);
  }
  // A virtual roll turns them like RollLabel does the stored keypoints.
  ViewLabel stored = label;
  for (int k = 0; k < kNumKeypoints; ++k) {
    for (int a = 0; a < 3; ++a) stored.keypoints[k][a] = static_cast<float>((*norm)[k][a]);
  }
  const float angle = RollAngle(5, 12);
  const ViewLabel rolled = RollLabel(stored, angle);
  auto turned = ViewKeypointsNormalised(rig, label, params, angle);
  ASSERT_TRUE(turned.ok());
  for (int k = 0; k < kNumKeypoints; ++k) {
    for (int a = 0; a < 3; ++a) EXPECT_NEAR((*turned)[k][a], rolled.keypoints[k][a], 1e-3);
  }
}

TEST(HandCamera, RollTurnsTheImageAboutItsCentre) {
  // Docs/conventions.md: a render with camera roll a equals the roll-0 render turned by a about
  // the image centre (x' = cos a x - sin a y, y' = sin a x + cos a y).
  const HandRig rig = ShippedRig();
  const RenderSettings params{200, 0.25};
  const Vec3d d{0.6, 0.0, 0.8};
  const double a = 0.7;
  auto r0 = CamFromHand(rig, d, 0.0);
  auto ra = CamFromHand(rig, d, a);
  ASSERT_TRUE(r0.ok() && ra.ok());
  for (const Vec3d& p : rig.Keypoints3d(kFist)) {
    const Vec3d u = ProjectToRenderPx(p, rig.look_at(), *r0, params);
    const Vec3d v = ProjectToRenderPx(p, rig.look_at(), *ra, params);
    const double x = u[0] - 100, y = u[1] - 100;
    EXPECT_NEAR(v[0] - 100, std::cos(a) * x - std::sin(a) * y, 1e-9);
    EXPECT_NEAR(v[1] - 100, std::sin(a) * x + std::cos(a) * y, 1e-9);
    EXPECT_NEAR(v[2], u[2], 1e-9);
  }
}

TEST(HandCamera, RefusesBadInput) {
  const HandRig rig = ShippedRig();
  EXPECT_EQ(CamFromHand(rig, {0, 0, 0}, 0).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(CamFromHand(rig, {NAN, 0, 1}, 0).status().code(), StatusCode::kInvalidArgument);
  // At the pole with the palm normal along the view direction there is no image up.
  EXPECT_FALSE(CamFromHandRotation({0, 0, 1}, {0, 0, 1}, {0, 0, 1}, 0).ok());
  ViewLabel label;  // scale 0: no normalisation recorded
  label.view_direction = {0, 0, 1};
  EXPECT_FALSE(ViewKeypointsNormalised(rig, label, RenderSettings{256, 0.3}).ok());
  EXPECT_FALSE(ViewKeypointsPx(rig, label, RenderSettings{0, 0.3}).ok());
}

TEST(RenderSettings, CheckAndMetadata) {
  EXPECT_TRUE((RenderSettings{256, 0.3}).Check());
  EXPECT_FALSE((RenderSettings{0, 0.3}).Check());
  EXPECT_FALSE((RenderSettings{256, 0}).Check());
  EXPECT_FALSE((RenderSettings{256, NAN}).Check());
  auto p = RenderSettings::FromMetadata(
      json{{"generation", {{"resolution", 128}, {"ortho_scale", 0.25}}}}, "db/manifest.json");
  ASSERT_TRUE(p.ok()) << p.status().message();
  EXPECT_EQ(p->resolution, 128);
  EXPECT_EQ(p->ortho_scale, 0.25);
  auto bad =
      RenderSettings::FromMetadata(json{{"generation", {{"resolution", 128}}}}, "db/manifest.json");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("db/manifest.json"), std::string::npos);
  EXPECT_NE(bad.status().message().find("ortho_scale"), std::string::npos);
  EXPECT_FALSE(RenderSettings::FromMetadata(json::object(), "m").ok());
}

}  // namespace
}  // namespace handdb
