#include "base/image_decode.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
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

fs::path Images() { return SourceDir() / "tests" / "data" / "images"; }

// A phone JPEG (100 x 100, EXIF orientation 1) from the development photos.
fs::path PhoneJpeg() {
  return SourceDir() / "tests" / "data" / "photos" / "asl-digits" / "asl-2" / "IMG_5362.JPG";
}

TEST(DecodeImage, DecodesEveryPngColourTypeToOpenCvsChannels) {
  struct Case {
    const char* file;
    int channels;
    int bytes;
  };
  for (const Case& c : {Case{"grey1.png", 1, 1},
                        Case{"grey16.png", 1, 2},
                        Case{"grey_alpha8.png", 4, 1},
                        Case{"rgb8.png", 3, 1},
                        Case{"rgb8_trns.png", 4, 1},
                        Case{"rgba16.png", 4, 2},
                        Case{"palette4.png", 3, 1},
                        Case{"palette8_trns.png", 4, 1},
                        Case{"rgb8_interlaced.png", 3, 1}}) {
    SCOPED_TRACE(c.file);
    auto img = DecodeImageFile(Images() / c.file);
    ASSERT_TRUE(img.ok()) << img.status().message();
    EXPECT_EQ(img->width, 23);
    EXPECT_EQ(img->height, 17);
    EXPECT_EQ(img->channels, c.channels);
    EXPECT_EQ(img->bytes_per_sample, c.bytes);
    EXPECT_EQ(img->pixels.size(), img->row_bytes() * 17);
    for (auto mode : {DecodeOptions::Mode::kGrey, DecodeOptions::Mode::kColor}) {
      auto as = DecodeImageFile(Images() / c.file, {mode});
      ASSERT_TRUE(as.ok()) << as.status().message();
      EXPECT_EQ(as->channels, mode == DecodeOptions::Mode::kGrey ? 1 : 3);
      EXPECT_EQ(as->bytes_per_sample, 1);
    }
  }
}

// libpng's errors were printed ("libpng error: ...") before handdb's own line; now they are the
// one line, naming the file.
TEST(DecodeImage, CorruptPngsAreOneErrorNamingTheFile) {
  for (const auto& [file, problem] : std::vector<std::pair<std::string, std::string>>{
           {"corrupt_crc.png", "corrupt PNG: IDAT: CRC error"},
           {"corrupt_filter.png", "corrupt PNG: bad adaptive filter value"},
           {"corrupt_zlib.png", "corrupt PNG: IDAT: invalid block type"},
           {"corrupt_ihdr.png", "corrupt PNG: Not enough image data"}}) {
    SCOPED_TRACE(file);
    ::testing::internal::CaptureStderr();
    auto img = DecodeImageFile(Images() / file);
    EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
    ASSERT_FALSE(img.ok());
    EXPECT_EQ(img.status().code(), StatusCode::kBadImage);
    EXPECT_EQ(img.status().message(), (Images() / file).string() + ": " + problem);
  }
}

// A JPEG whose entropy-coded data is damaged decoded with libjpeg's "Corrupt JPEG data" warning
// on stderr and grey blocks in the picture; now it is refused.
TEST(DecodeImage, CorruptJpegIsRefusedNotSearched) {
  std::vector<uint8_t> bytes = testing::ReadBytes(PhoneJpeg());
  auto whole = DecodeImage(bytes, "phone.jpg", {DecodeOptions::Mode::kColor, 2});
  ASSERT_TRUE(whole.ok()) << whole.status().message();
  EXPECT_EQ(whole->width, 50);
  EXPECT_EQ(whole->height, 50);
  size_t sos = 0;
  for (size_t i = 0; i + 1 < bytes.size(); ++i) {
    if (bytes[i] == 0xFF && bytes[i + 1] == 0xDA) {
      sos = i;
      break;
    }
  }
  ASSERT_GT(sos, 0u);
  ASSERT_GT(bytes.size(), sos + 1000);
  for (size_t i = sos + 200; i < sos + 260; ++i) bytes[i] ^= 0xA5;
  ::testing::internal::CaptureStderr();
  auto corrupt = DecodeImage(bytes, "phone.jpg", {DecodeOptions::Mode::kColor, 2});
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
  ASSERT_FALSE(corrupt.ok());
  EXPECT_EQ(corrupt.status().code(), StatusCode::kBadImage);
  EXPECT_EQ(corrupt.status().message().rfind("phone.jpg: corrupt JPEG: ", 0), 0u)
      << corrupt.status().message();
}

TEST(DecodeImage, OtherFormatsAndTooManyPixelsAreRefusedBeforeDecoding) {
  const std::vector<uint8_t> tiff = {'I', 'I', 42, 0, 8, 0, 0, 0, 0, 0};
  auto img = DecodeImage(tiff, "big.tif");
  ASSERT_FALSE(img.ok());
  EXPECT_EQ(img.status().message(), "big.tif: not a PNG or JPEG image");
  DecodeOptions small;
  small.max_pixels = 100;
  img = DecodeImageFile(Images() / "rgb8.png", small);
  ASSERT_FALSE(img.ok());
  EXPECT_EQ(img.status().message(),
            (Images() / "rgb8.png").string() +
                ": 23 x 17 pixels (PNG), more than the 100 (0 Mpx) allowed");
  EXPECT_EQ(SniffImageFormat(tiff), ImageFormat::kUnknown);
  const std::vector<uint8_t> pgm = {'P', '5', '\n', '1'};
  EXPECT_EQ(SniffImageFormat(pgm), ImageFormat::kPnm);
}

TEST(DecodeOptions, Check) {
  DecodeOptions o;
  EXPECT_TRUE(o.Check());
  o.reduce = 3;
  EXPECT_FALSE(o.Check());
  o = {DecodeOptions::Mode::kGrey, 2};  // reduced reads are colour, as IMREAD_REDUCED_COLOR_*
  EXPECT_FALSE(o.Check());
}

}  // namespace
}  // namespace handdb
