#include "evaluate/plots.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <opencv2/imgcodecs.hpp>

#include "base/atomic_file.h"
#include "base/testing.h"

namespace handdb {
namespace {

class EvalPlots : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ =
        handdb::testing::TempDir(std::string("eval_plots_") +
                                 ::testing::UnitTest::GetInstance()->current_test_info()->name());
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

bool IsWhite(const cv::Vec3b& p) { return p[0] == 255 && p[1] == 255 && p[2] == 255; }

// Counts non-white pixels in a rectangle.
int Ink(const cv::Mat& image, cv::Rect r) {
  int n = 0;
  for (int y = r.y; y < r.y + r.height; ++y) {
    for (int x = r.x; x < r.x + r.width; ++x) n += IsWhite(image.at<cv::Vec3b>(y, x)) ? 0 : 1;
  }
  return n;
}

TEST_F(EvalPlots, RankHistogramDrawsBarsWhereCountsAre) {
  RankTable table;
  table.counts = {10, 0, 0, 0, 0, 0, 5};
  const auto path = dir_ / "ranks.png";
  ASSERT_TRUE(WriteRankHistogramPng(path, table, "test").ok());
  const cv::Mat image = cv::imread(path.string(), cv::IMREAD_COLOR);
  ASSERT_EQ(image.cols, 760);
  ASSERT_EQ(image.rows, 420);
  // Plot area: x 60..740 (7 slots of 97 px), bars end at y = 360. Sample half-way up the tallest
  // bar inside each slot's middle third.
  const int slot = (760 - 60 - 20) / 7;
  auto bar_sample = [&](int bin, int y) {
    return Ink(image, cv::Rect(60 + bin * slot + slot / 3, y, slot / 3, 10));
  };
  // (y 215..225 and 145..155 avoid the grid lines at 205 and 127.)
  EXPECT_GT(bar_sample(0, 215), 0);  // full-height bar (count 10)
  EXPECT_EQ(bar_sample(1, 215), 0);  // empty bin
  EXPECT_GT(bar_sample(6, 300), 0);  // half-height bar (count 5)
  EXPECT_EQ(bar_sample(6, 145), 0);  // ... that does not reach the top
}

TEST_F(EvalPlots, CdfAndExampleSheetAreWritten) {
  CdfSeries a{"top-1", {0.1, 0.2, std::numeric_limits<double>::quiet_NaN(), 0.4}, {200, 0, 0}};
  CdfSeries b{"best of 10", {0.05, 0.1, 0.1}, {0, 0, 200}};
  const auto cdf_path = dir_ / "cdf.png";
  ASSERT_TRUE(WriteCdfPng(cdf_path, {a, b}, "keypoint error", "error / hand size", 0).ok());
  EXPECT_FALSE(cv::imread(cdf_path.string()).empty());

  ExampleTile tile;
  tile.caption = "test 0";
  for (int i = 0; i < 360; ++i) {
    const double t = i * M_PI / 180;
    tile.query_points.push_back(
        {static_cast<float>(96 * std::cos(t)), static_cast<float>(96 * std::sin(t))});
  }
  tile.match_points = {{0, 0}};
  tile.image = dir_ / "missing.png";  // unreadable: a grey box, not an error
  const auto sheet_path = dir_ / "sheet.png";
  ASSERT_TRUE(WriteExampleSheetPng(sheet_path, {tile, tile, tile}, "examples").ok());
  const cv::Mat sheet = cv::imread(sheet_path.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(sheet.empty());
  EXPECT_EQ(sheet.cols, 2 * (2 * 220 + 10));
  // The circle of query points passes through the right-hand panel's centre row.
  // Radius 96 normalised px at 220 / (1.25 * 192) panel px per normalised px: 88 px.
  const cv::Vec3b at_circle = sheet.at<cv::Vec3b>(36 + 110, 220 + 110 + 88);
  EXPECT_EQ(at_circle, cv::Vec3b(200, 90, 20));
  const cv::Vec3b at_match = sheet.at<cv::Vec3b>(36 + 110, 220 + 110);
  EXPECT_EQ(at_match, cv::Vec3b(40, 40, 220));
}

TEST_F(EvalPlots, UnwritableDirectoryIsAnError) {
  RankTable table;
  ASSERT_TRUE(WriteFileAtomic(dir_ / "file", "x").ok());
  const Status status = WriteRankHistogramPng(dir_ / "file" / "ranks.png", table, "x");
  EXPECT_FALSE(status.ok());
}

}  // namespace
}  // namespace handdb
