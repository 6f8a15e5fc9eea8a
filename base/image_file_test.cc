#include "base/image_file.h"

#include <gtest/gtest.h>

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

// Issue 14 item 6: a truncated JPEG or PNG decoded with only a library warning.
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

TEST(ImageFile, NotARegularFileIsRefused) {
  const auto dir = testing::TempDir("image_file_dir");
  const Status s = CheckImageFileComplete(dir);
  EXPECT_EQ(s.message(), dir.string() + ": is a directory, expected a file");
}

}  // namespace
}  // namespace handdb
