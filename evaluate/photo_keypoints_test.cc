#include "evaluate/photo_keypoints.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "base/json_schema.h"
#include "base/testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// 21 keypoints on a 3 x 7 grid, 10 px apart, from (100, 50): bounding box 20 x 60.
json GridKeypoints() {
  json kps = json::array();
  for (int k = 0; k < kNumKeypoints; ++k) kps.push_back({100 + 10 * (k % 3), 50 + 10 * (k / 3)});
  return kps;
}

json Doc(json images) {
  return {{"format", "handdb-photo-keypoints"}, {"version", 1}, {"images", std::move(images)}};
}

// Writes `doc` to a file and reads it back as --keypoints does.
Result<PhotoKeypointFile> ReadDoc(const json& doc, const std::string& name = "kp.json") {
  static const fs::path dir = testing::TempDir("photo_keypoints");
  fs::create_directories(dir);
  std::ofstream(dir / name) << doc.dump();
  return ReadPhotoKeypoints(dir / name);
}

TEST(PhotoKeypoints, ReadsKeypointsVisibilityAndHandSize) {
  json hidden = GridKeypoints();
  hidden[20] = {900, 900, false};  // not visible: ignored, also for the hand size
  hidden[3] = {110, 60, true};
  auto file = ReadDoc(Doc({{"asl-3/a.jpg", GridKeypoints()}, {"asl-3/b.png", hidden}}));
  ASSERT_TRUE(file.ok()) << file.status().message();
  ASSERT_EQ(file->images.size(), 2u);
  const PhotoKeypoints& a = file->images.at("asl-3/a.jpg");
  EXPECT_EQ(a.NumVisible(), 21);
  EXPECT_FLOAT_EQ(a.px[4].x, 110);
  EXPECT_FLOAT_EQ(a.px[4].y, 60);
  EXPECT_DOUBLE_EQ(a.hand_size_px, std::hypot(20.0, 60.0));
  const PhotoKeypoints& b = file->images.at("asl-3/b.png");
  EXPECT_EQ(b.NumVisible(), 20);
  EXPECT_FALSE(b.visible[20]);
  EXPECT_FLOAT_EQ(b.px[3].x, 110);  // [x, y, true] is an ordinary keypoint
  // The hidden keypoint at (900, 900) does not stretch the box: still 20 x 60.
  EXPECT_DOUBLE_EQ(b.hand_size_px, std::hypot(20.0, 60.0));
}

TEST(PhotoKeypoints, DistancesSkipHiddenKeypointsAndNormaliseByHandSize) {
  PhotoKeypoints truth;
  for (int k = 0; k < kNumKeypoints; ++k) {
    truth.px[k] = {static_cast<float>(10 * k), 0};
    truth.visible[k] = k != 5;
  }
  truth.hand_size_px = HandSizePx(truth);
  EXPECT_DOUBLE_EQ(truth.hand_size_px, 200);
  std::vector<Point2f> predicted(truth.px.begin(), truth.px.end());
  for (Point2f& p : predicted) p.y += 3;  // 3 px off everywhere
  predicted[7].x += 4;                    // 5 px off
  const auto d = KeypointDistancesPx(truth, predicted);
  EXPECT_TRUE(std::isnan(d[5]));
  EXPECT_DOUBLE_EQ(d[0], 3);
  EXPECT_DOUBLE_EQ(d[7], 5);
  // 19 keypoints at 3 px and one at 5 px, over a hand of 200 px.
  EXPECT_DOUBLE_EQ(MeanKeypointError(d, truth.hand_size_px), (19 * 3.0 + 5) / 20 / 200);
  std::array<double, kNumKeypoints> none;
  none.fill(std::nan(""));
  EXPECT_TRUE(std::isnan(MeanKeypointError(none, 200)));
}

// Every problem is one line naming the file, the image and what is wrong.
TEST(PhotoKeypoints, BadFilesAreOneLineErrorsNamingTheFileAndImage) {
  auto expect_error = [](const json& doc, const std::string& what) {
    auto file = ReadDoc(doc, "bad.json");
    ASSERT_FALSE(file.ok()) << what;
    const std::string& m = file.status().message();
    EXPECT_NE(m.find("bad.json"), std::string::npos) << m;
    EXPECT_NE(m.find(what), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  };
  json twenty = GridKeypoints();
  twenty.erase(twenty.end() - 1);
  expect_error(Doc({{"a/x.jpg", twenty}}), "minItems is 21");
  json word = GridKeypoints();
  word[2] = {"1", 2};
  expect_error(Doc({{"a/x.jpg", word}}), "x.jpg/2/0");
  json flag = GridKeypoints();
  flag[2] = {1, 2, 1};
  expect_error(Doc({{"a/x.jpg", flag}}), "x.jpg/2/2");
  expect_error(Doc({{"../a/x.jpg", GridKeypoints()}}), "images[\"../a/x.jpg\"]: not a path");
  expect_error(Doc({{"/a/x.jpg", GridKeypoints()}}), "not a path relative");
  expect_error(Doc({{"a//x.jpg", GridKeypoints()}}), "not a path relative");
  json hidden = GridKeypoints();
  for (int k = 1; k < kNumKeypoints; ++k) hidden[k] = {0, 0, false};
  expect_error(Doc({{"a/x.jpg", hidden}}), "images[\"a/x.jpg\"]: 1 visible keypoints");
  json point = json::array();
  for (int k = 0; k < kNumKeypoints; ++k) point.push_back({5, 5});
  expect_error(Doc({{"a/x.jpg", point}}), "every visible keypoint is at the same point");
  json huge = GridKeypoints();
  huge[0] = {1e300, 0};
  expect_error(Doc({{"a/x.jpg", huge}}), "too large for a pixel coordinate");
  json other = Doc({{"a/x.jpg", GridKeypoints()}});
  other["format"] = "coco";
  expect_error(other, "/format");
  expect_error(json{{"images", json::object()}}, "format");
}

TEST(PhotoKeypoints, SchemaAcceptsTheDocumentedForms) {
  json kps = GridKeypoints();
  kps[0] = {1.5, 2.25, true};
  kps[1] = {1, 2, false};
  json doc = Doc({{"asl-1/IMG_0001.JPG", kps}});
  doc["description"] = "hand-annotated";
  EXPECT_TRUE(ValidateJson(doc, "photo_keypoints.schema.json", "doc").ok());
  EXPECT_TRUE(ValidateJson(Doc(json::object()), "photo_keypoints.schema.json", "doc").ok());
  auto missing = ReadPhotoKeypoints("/nonexistent/keypoints.json");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("/nonexistent/keypoints.json"), std::string::npos);
}

}  // namespace
}  // namespace handdb
