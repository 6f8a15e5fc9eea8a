#include "base/mapped_file.h"

#include <gtest/gtest.h>

#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <utility>

#include "base/atomic_file.h"
#include "base/testing.h"

// GCC names AddressSanitizer with __SANITIZE_ADDRESS__, clang with __has_feature.
#if defined(__SANITIZE_ADDRESS__)
#define HANDDB_TEST_UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define HANDDB_TEST_UNDER_ASAN 1
#endif
#endif
#ifndef HANDDB_TEST_UNDER_ASAN
#define HANDDB_TEST_UNDER_ASAN 0
#endif

namespace handdb {
namespace {

std::filesystem::path TempPath(const std::string& name) {
  return testing::TempDir("mapped") / name;
}

TEST(MappedFile, MapsTheBytesAndMoves) {
  const auto path = TempPath("abc");
  ASSERT_TRUE(WriteFileAtomic(path, "abc").ok());
  auto file = MappedFile::Open(path, MappedFile::Advice::kSequential);
  ASSERT_TRUE(file.ok()) << file.status().ToString();
  ASSERT_EQ(file->size(), 3u);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(file->bytes().data()), 3), "abc");
  MappedFile moved = std::move(file).value();
  EXPECT_EQ(moved.size(), 3u);
  MappedFile other;
  other = std::move(moved);
  EXPECT_EQ(other.bytes()[2], 'c');
  other.Advise(0, 4096, MappedFile::Advice::kDontNeed);  // pages fault back in from the file
  EXPECT_EQ(other.bytes()[0], 'a');
  EXPECT_THROW(other.Advise(1, 2, MappedFile::Advice::kNormal), std::logic_error);
  EXPECT_EQ(moved.size(), 0u);  // NOLINT(bugprone-use-after-move): moved-from is empty
  std::filesystem::remove(path);
}

TEST(MappedFile, EmptyFileIsAnEmptySpan) {
  const auto path = TempPath("empty");
  ASSERT_TRUE(WriteFileAtomic(path, "").ok());
  auto file = MappedFile::Open(path);
  ASSERT_TRUE(file.ok());
  EXPECT_TRUE(file->bytes().empty());
  std::filesystem::remove(path);
}

TEST(MappedFile, ErrorsNameThePath) {
  const auto missing = TempPath("missing");
  auto file = MappedFile::Open(missing);
  ASSERT_FALSE(file.ok());
  EXPECT_EQ(file.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(file.status().message(), missing.string() + ": no such file");
  const auto dir = std::filesystem::temp_directory_path();
  auto not_regular = MappedFile::Open(dir);
  ASSERT_FALSE(not_regular.ok());
  EXPECT_EQ(not_regular.status().code(), StatusCode::kIoError);
  EXPECT_EQ(not_regular.status().message(), dir.string() + ": is a directory, expected a file");
}

// A file truncated while mapped: the read past its new end is one line naming the file and exit
// status 1, not a SIGBUS (status 135 from a shell).
TEST(MappedFileDeathTest, TruncatedWhileMappedIsOneLineAndExitOne) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const auto path = TempPath("truncated");
  ASSERT_TRUE(WriteFileAtomic(path, std::string(3 * 4096, 'x')).ok());
  EXPECT_EXIT(
      {
        auto file = MappedFile::Open(path);
        if (!file.ok()) std::_Exit(3);
        std::filesystem::resize_file(path, 0);
        volatile uint8_t byte = file->bytes()[2 * 4096];
        (void)byte;
        std::_Exit(4);  // not reached: the read faults
      },
      ::testing::ExitedWithCode(1),
      // The threadsafe style runs the test again in the child, with its own temp dir.
      "^handdb: /.*/handdb_test_mapped_[0-9]+/truncated: changed or truncated while being "
      "read\n$");
  // A SIGBUS outside every mapping goes on to the handler installed before ours: the default
  // one kills the process; AddressSanitizer's (a sanitizer build) reports and aborts instead.
#if !HANDDB_TEST_UNDER_ASAN
  EXPECT_EXIT(
      {
        auto file = MappedFile::Open(path);
        std::raise(SIGBUS);
      },
      ::testing::KilledBySignal(SIGBUS),
      "");
#endif
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace handdb
