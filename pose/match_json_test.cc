#include "pose/match_json.h"

#include <gtest/gtest.h>

#include <cmath>

#include "query/search_testing.h"

namespace handdb {
namespace {

Match SomeMatch() {
  Match m;
  m.view_id = 7;
  m.roll = 3;
  m.roll_angle = -M_PI / 2;
  m.distance = 1.25;
  m.shape_name = "asl-5";
  m.hand = Hand::kLeft;
  m.label = testing::SyntheticViewLabel(7, 1);
  return m;
}

TEST(MatchJsonTest, RollDegreesLieInZeroTo360) {
  EXPECT_DOUBLE_EQ(RollDegrees0To360(M_PI / 2), 90.0);
  EXPECT_DOUBLE_EQ(RollDegrees0To360(-M_PI / 2), 270.0);
  EXPECT_EQ(RollDegrees0To360(2 * M_PI), 0.0);
  EXPECT_EQ(RollDegrees0To360(0), 0.0);
}

TEST(MatchJsonTest, WritesTheMatchAndItsKeypointsInThePicture) {
  const Match m = SomeMatch();
  QueryEdges query;
  query.centre_x = 50;
  query.centre_y = 60;
  query.scale = 2;
  const nlohmann::json j = MatchToJson(m, 4, &query);
  EXPECT_EQ(j.at("rank"), 4);
  EXPECT_EQ(j.at("view_id"), 7);
  EXPECT_EQ(j.at("roll"), 3);
  EXPECT_EQ(j.at("roll_deg").get<double>(), RollDegrees0To360(m.roll_angle));
  EXPECT_NEAR(j.at("roll_deg").get<double>(), 270.0, 1e-4);  // a float angle
  EXPECT_EQ(j.at("distance").get<double>(), 1.25);
  EXPECT_EQ(j.at("shape_name"), "asl-5");
  EXPECT_EQ(j.at("hand"), "left");
  EXPECT_EQ(j.at("shape_id"), m.label.shape_id);
  EXPECT_EQ(j.at("view_theta_deg").get<double>(), m.label.view_theta * 180.0 / M_PI);
  ASSERT_EQ(j.at("keypoints").size(), static_cast<size_t>(kNumKeypoints));
  ASSERT_EQ(j.at("keypoints_image_px").size(), static_cast<size_t>(kNumKeypoints));
  for (int k = 0; k < kNumKeypoints; ++k) {
    const auto& kp = m.label.keypoints[k];
    EXPECT_EQ(j["keypoints"][k][0].get<float>(), kp[0]);
    EXPECT_EQ(j["keypoints"][k][2].get<float>(), kp[2]);
    const Point2f p = query.ImageFromNormalised({kp[0], kp[1]});
    EXPECT_EQ(j["keypoints_image_px"][k][0].get<float>(), p.x);
    EXPECT_EQ(j["keypoints_image_px"][k][1].get<float>(), p.y);
  }
  // Not re-ranked by landmarks: no score.
  EXPECT_FALSE(j.contains("score"));
  EXPECT_FALSE(j.contains("landmark_error"));
}

TEST(MatchJsonTest, ScoreWhenReRankedAndNoPictureKeypointsWithoutAPicture) {
  Match m = SomeMatch();
  m.score = 1.5;
  m.landmark_error = 0.25;
  const nlohmann::json j = MatchToJson(m, 1, nullptr);
  EXPECT_EQ(j.at("score").get<double>(), 1.5);
  EXPECT_EQ(j.at("landmark_error").get<double>(), 0.25);
  EXPECT_FALSE(j.contains("keypoints_image_px"));
  EXPECT_TRUE(j.contains("keypoints"));
}

}  // namespace
}  // namespace handdb
