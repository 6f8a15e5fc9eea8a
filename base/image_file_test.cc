#include "base/image_file.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>

#include "base/atomic_file.h"
#include "base/testing.h"

namespace handdb {
namespace {

const std::string kPngSignature("\x89PNG\r\n\x1A\n", 8);
const std::string kPngEnd("\0\0\0\0IEND\xAE\x42\x60\x82", 12);
const std::string kJpegStart("\xFF\xD8\xFF\xE0", 4);
const std::string kJpegEnd("\xFF\xD9", 2);

Status Check(const std::string& name, const std::string& bytes) {
  const auto dir = testing::TempDir("image_file");
  EXPECT_TRUE(WriteFileAtomic(dir / name, bytes).ok());
  return CheckImageFileComplete(dir / name);
}

// A truncated JPEG or PNG is refused (decoders accept it with only a library warning).
TEST(ImageFile, CompleteFilesPass) {
  const std::string body(10000, 'x');
  EXPECT_TRUE(Check("a.png", kPngSignature + body + kPngEnd).ok());
  EXPECT_TRUE(Check("a.jpg", kJpegStart + body + kJpegEnd).ok());
  EXPECT_TRUE(Check("b.jpg", kJpegStart + body + kJpegEnd + std::string(100, '\0')).ok());
  EXPECT_TRUE(Check("a.pgm", "P5\n1 1\n255\n\x01").ok());  // not checked
}

TEST(ImageFile, TruncatedFilesAreRefused) {
  const std::string body(10000, 'x');
  const Status png = Check("t.png", kPngSignature + body);
  EXPECT_EQ(png.code(), StatusCode::kBadImage);
  EXPECT_NE(png.message().find("t.png: truncated PNG (no IEND chunk)"), std::string::npos)
      << png.message();
  // The end marker far before the end (a thumbnail) does not count.
  const Status jpg = Check("t.jpg", kJpegStart + kJpegEnd + body);
  EXPECT_EQ(jpg.code(), StatusCode::kBadImage);
  EXPECT_NE(jpg.message().find("t.jpg: truncated JPEG (no end-of-image marker)"), std::string::npos)
      << jpg.message();
  EXPECT_FALSE(Check("short.png", kPngSignature).ok());
}

std::string Be32(uint32_t v) {
  return {static_cast<char>(v >> 24),
          static_cast<char>(v >> 16),
          static_cast<char>(v >> 8),
          static_cast<char>(v)};
}
std::string Be16(uint32_t v) { return {static_cast<char>(v >> 8), static_cast<char>(v)}; }
std::string Le32(uint32_t v) {
  return {static_cast<char>(v),
          static_cast<char>(v >> 8),
          static_cast<char>(v >> 16),
          static_cast<char>(v >> 24)};
}

// A complete PNG whose IHDR says w x h (the pixel data need not be there for the header check).
std::string Png(uint32_t w, uint32_t h) {
  return kPngSignature + Be32(13) + "IHDR" + Be32(w) + Be32(h) + std::string("\x08\x02\0\0\0", 5) +
         Be32(0) + kPngEnd;
}
// A JPEG: SOI, an APP0 segment of 300 bytes, a comment, then SOF0 with w x h, EOI.
std::string Jpeg(uint32_t w, uint32_t h) {
  return std::string("\xFF\xD8", 2) + "\xFF\xE0" + Be16(302) + std::string(300, 'a') + "\xFF\xFE" +
         Be16(4) + "hi" + "\xFF\xC0" + Be16(17) + "\x08" + Be16(h) + Be16(w) +
         std::string(12, '\1') + kJpegEnd;
}

// A 20000 x 20000 PNG (5 MB) would peak at 6.1 GB in `query`; a header claiming 100000 x 100000
// would get OpenCV's message without the file. Refused from the header, one line.
TEST(ImageFile, ImagesAboveThePixelLimitAreRefusedFromTheHeader) {
  const auto dir = testing::TempDir("image_size");
  ASSERT_TRUE(WriteFileAtomic(dir / "p.png", Png(640, 480)).ok());
  ASSERT_TRUE(WriteFileAtomic(dir / "j.jpg", Jpeg(4000, 3000)).ok());
  auto png = ReadImageSize(dir / "p.png");
  ASSERT_TRUE(png.has_value());
  EXPECT_EQ(png->width, 640u);
  EXPECT_EQ(png->height, 480u);
  auto jpg = ReadImageSize(dir / "j.jpg");
  ASSERT_TRUE(jpg.has_value());
  EXPECT_EQ(jpg->width, 4000u);
  EXPECT_EQ(jpg->height, 3000u);
  EXPECT_STREQ(jpg->format, "JPEG");

  EXPECT_TRUE(Check("limit.png", Png(8192, 8192)).ok());  // exactly kMaxImagePixels
  const Status big = Check("big.png", Png(20000, 20000));
  EXPECT_EQ(big.code(), StatusCode::kBadImage);
  EXPECT_NE(big.message().find("big.png: 20000 x 20000 pixels (PNG header), more than the "
                               "67108864 (64 Mpx) allowed"),
            std::string::npos)
      << big.message();
  EXPECT_NE(Check("huge.png", Png(100000, 100000)).message().find("100000 x 100000 pixels"),
            std::string::npos);
  EXPECT_NE(Check("big.jpg", Jpeg(8193, 8192)).message().find("8193 x 8192 pixels (JPEG header)"),
            std::string::npos);
  EXPECT_NE(Check("big.pgm", "P5\n# made by hand\n10000 7000\n255\n")
                .message()
                .find("10000 x 7000 pixels (PNM header)"),
            std::string::npos);
  EXPECT_NE(Check("big.bmp",
                  "BM" + std::string(16, '\0') + Le32(9000) + Le32(static_cast<uint32_t>(-9000)) +
                      std::string(40, '\0'))
                .message()
                .find("9000 x 9000 pixels (BMP header)"),
            std::string::npos);
  EXPECT_TRUE(Check("small.pgm", "P5\n300 200\n255\n").ok());
}

TEST(ImageFile, NotARegularFileIsRefused) {
  const auto dir = testing::TempDir("image_file_dir");
  const Status s = CheckImageFileComplete(dir);
  EXPECT_EQ(s.message(), dir.string() + ": is a directory, expected a file");
}

}  // namespace
}  // namespace handdb
