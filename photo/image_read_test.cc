#include "photo/image_read.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "base/testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

fs::path SourceDir() {
  const char* dir = std::getenv("HANDDB_SOURCE_DIR");
  return dir != nullptr ? fs::path(dir) : fs::path(".");
}

// Same type, size and bytes.
::testing::AssertionResult SamePixels(const cv::Mat& a, const cv::Mat& b) {
  if (a.type() != b.type() || a.size() != b.size()) {
    return ::testing::AssertionFailure()
           << "type " << a.type() << " " << a.cols << "x" << a.rows << " vs type " << b.type()
           << " " << b.cols << "x" << b.rows;
  }
  cv::Mat diff = a != b;
  if (diff.channels() > 1) diff = diff.reshape(1);
  const int differing = cv::countNonZero(diff);
  if (differing != 0) return ::testing::AssertionFailure() << differing << " samples differ";
  return ::testing::AssertionSuccess();
}

void ExpectAsImread(const fs::path& file, const std::vector<int>& flags) {
  for (int flag : flags) {
    SCOPED_TRACE(file.string() + " flags " + std::to_string(flag));
    const cv::Mat expected = cv::imread(file.string(), flag);
    ASSERT_FALSE(expected.empty());
    auto got = ReadImage(file, flag);
    ASSERT_TRUE(got.ok()) << got.status().message();
    EXPECT_TRUE(SamePixels(*got, expected));
  }
}

const std::vector<int> kFlags = {
    cv::IMREAD_UNCHANGED, cv::IMREAD_GRAYSCALE, cv::IMREAD_COLOR, cv::IMREAD_REDUCED_COLOR_2};

// Every PNG colour type and bit depth (grey 1-16 bits, alpha, tRNS, palettes, 16-bit, Adam7).
TEST(ReadImage, PngsAsImreadReadsThem) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(SourceDir() / "tests" / "data" / "images")) {
    const std::string name = e.path().filename().string();
    if (e.path().extension() != ".png" || name.rfind("corrupt_", 0) == 0) continue;
    ExpectAsImread(e.path(), kFlags);
    ++n;
  }
  EXPECT_EQ(n, 22);
}

// The development photos are phone JPEGs with EXIF orientations: applied except in
// IMREAD_UNCHANGED, as imread does; reduced reads scale inside libjpeg.
TEST(ReadImage, PhoneJpegsAsImreadReadsThem) {
  int n = 0;
  for (const auto& e :
       fs::recursive_directory_iterator(SourceDir() / "tests" / "data" / "photos")) {
    if (e.path().extension() != ".JPG") continue;
    ExpectAsImread(e.path(),
                   n < 4 ? std::vector<int>{cv::IMREAD_UNCHANGED,
                                            cv::IMREAD_GRAYSCALE,
                                            cv::IMREAD_COLOR,
                                            cv::IMREAD_REDUCED_COLOR_2,
                                            cv::IMREAD_REDUCED_COLOR_4,
                                            cv::IMREAD_REDUCED_COLOR_8}
                         : std::vector<int>{cv::IMREAD_UNCHANGED});
    ++n;
  }
  EXPECT_GT(n, 0);
}

// Grey, progressive and every EXIF orientation, written here.
TEST(ReadImage, GreyProgressiveAndRotatedJpegsAsImreadReadsThem) {
  const fs::path dir = testing::TempDir("image_read");
  cv::Mat bgr(37, 53, CV_8UC3);
  cv::randu(bgr, 0, 255);
  cv::Mat grey;
  cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  ASSERT_TRUE(cv::imwrite((dir / "grey.jpg").string(), grey));
  ASSERT_TRUE(
      cv::imwrite((dir / "progressive.jpg").string(), bgr, {cv::IMWRITE_JPEG_PROGRESSIVE, 1}));
  ExpectAsImread(dir / "grey.jpg", kFlags);
  ExpectAsImread(dir / "progressive.jpg", kFlags);
  // An APP1 Exif segment (little-endian TIFF, one IFD0 entry: orientation) after SOI.
  std::vector<uint8_t> jpeg = testing::ReadBytes(dir / "progressive.jpg");
  for (int orientation = 1; orientation <= 8; ++orientation) {
    const std::vector<uint8_t> app1 = {0xFF,
                                       0xE1,
                                       0,
                                       34,
                                       'E',
                                       'x',
                                       'i',
                                       'f',
                                       0,
                                       0,
                                       'I',
                                       'I',
                                       42,
                                       0,
                                       8,
                                       0,
                                       0,
                                       0,
                                       1,
                                       0,
                                       0x12,
                                       0x01,
                                       3,
                                       0,
                                       1,
                                       0,
                                       0,
                                       0,
                                       static_cast<uint8_t>(orientation),
                                       0,
                                       0,
                                       0,
                                       0,
                                       0,
                                       0,
                                       0};
    std::vector<uint8_t> rotated(jpeg.begin(), jpeg.begin() + 2);
    rotated.insert(rotated.end(), app1.begin(), app1.end());
    rotated.insert(rotated.end(), jpeg.begin() + 2, jpeg.end());
    const fs::path file = dir / ("o" + std::to_string(orientation) + ".jpg");
    testing::WriteBytes(file, rotated);
    ExpectAsImread(file, {cv::IMREAD_UNCHANGED, cv::IMREAD_COLOR, cv::IMREAD_REDUCED_COLOR_2});
  }
  fs::remove_all(dir);
}

TEST(ReadImage, PnmGoesThroughOpenCvAndOtherFormatsAreRefused) {
  const fs::path dir = testing::TempDir("image_read_formats");
  cv::Mat grey(9, 11, CV_8UC1);
  cv::randu(grey, 0, 255);
  ASSERT_TRUE(cv::imwrite((dir / "a.pgm").string(), grey));
  ExpectAsImread(dir / "a.pgm", kFlags);
  ASSERT_TRUE(cv::imwrite((dir / "a.tiff").string(), grey));
  auto tiff = ReadImage(dir / "a.tiff", cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(tiff.ok());
  EXPECT_EQ(tiff.status().message(),
            (dir / "a.tiff").string() + ": not a PNG, JPEG, PNM or BMP image (the formats read)");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace handdb
