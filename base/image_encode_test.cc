// EncodePng writes the bytes cv::imencode(".png") writes (OpenCV is linked by this test only)
// and decodes back to the same pixels.
#include "base/image_encode.h"

#include <gtest/gtest.h>

#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "base/image_decode.h"

namespace handdb {
namespace {

cv::Mat Pattern(int width, int height, int channels) {
  cv::Mat m(height, width, CV_8UC(channels));
  cv::RNG rng(7);
  // Smooth ramps and a noisy band, so the filter and the compression both matter.
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width * channels; ++x) {
      m.ptr<uint8_t>(y)[x] =
          static_cast<uint8_t>(y < height / 2 ? (x + 3 * y) & 0xFF : rng.uniform(0, 256));
    }
  }
  return m;
}

PngPixels Pixels(const cv::Mat& m) { return {m.data, m.cols, m.rows, m.channels(), m.step[0]}; }

TEST(EncodePng, WritesTheBytesOfOpenCv) {
  for (int channels : {1, 3, 4}) {
    for (const cv::Size size : {cv::Size(1, 1), cv::Size(37, 11), cv::Size(384, 384)}) {
      const cv::Mat m = Pattern(size.width, size.height, channels);
      std::vector<uint8_t> want;
      ASSERT_TRUE(cv::imencode(".png", m, want));
      auto got = EncodePng(Pixels(m));
      ASSERT_TRUE(got.ok()) << got.status().message();
      EXPECT_EQ(*got, want) << channels << " channels, " << size.width << " x " << size.height;
    }
  }
}

TEST(EncodePng, RowsWithPaddingAndARoundTrip) {
  const cv::Mat whole = Pattern(50, 20, 3);
  const cv::Mat part = whole(cv::Rect(5, 2, 31, 17));  // rows longer than the width
  auto png = EncodePng(Pixels(part));
  ASSERT_TRUE(png.ok());
  DecodeOptions options;
  options.mode = DecodeOptions::Mode::kColor;
  auto back = DecodeImage(*png, "part.png", options);
  ASSERT_TRUE(back.ok()) << back.status().message();
  ASSERT_EQ(back->width, 31);
  ASSERT_EQ(back->height, 17);
  ASSERT_EQ(back->channels, 3);
  for (int y = 0; y < 17; ++y) {
    EXPECT_EQ(0, std::memcmp(back->pixels.data() + back->row_bytes() * y, part.ptr(y), 31 * 3));
  }
}

TEST(EncodePng, RefusesWhatItCannotWrite) {
  const uint8_t pixel[8] = {};
  EXPECT_EQ(EncodePng({pixel, 1, 1, 2, 2}).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(EncodePng({pixel, 0, 1, 1, 1}).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(EncodePng({nullptr, 1, 1, 1, 1}).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(EncodePng({pixel, 2, 1, 3, 5}).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace handdb
