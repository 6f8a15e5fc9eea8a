#include "base/atomic_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>

#include "base/testing.h"

namespace handdb {
namespace {

using testing::TempDir;

TEST(AtomicFile, WritesAndRenames) {
  auto dir = TempDir("writes");
  ASSERT_TRUE(WriteFileAtomic(dir / "a.txt", "hello").ok());
  auto content = ReadFileToString(dir / "a.txt");
  ASSERT_TRUE(content.ok());
  EXPECT_EQ(*content, "hello");
  // No temp files left behind.
  int n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir)) ++n;
  EXPECT_EQ(n, 1);
}

TEST(AtomicFile, AbortLeavesNothing) {
  auto dir = TempDir("abort");
  {
    AtomicFileWriter w;
    ASSERT_TRUE(w.Open(dir / "b.bin").ok());
    ASSERT_TRUE(w.Write("partial").ok());
  }  // destroyed without Commit
  EXPECT_FALSE(std::filesystem::exists(dir / "b.bin"));
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

TEST(AtomicFile, ReplacesExistingOnlyOnCommit) {
  auto dir = TempDir("replace");
  ASSERT_TRUE(WriteFileAtomic(dir / "c.txt", "old").ok());
  AtomicFileWriter w;
  ASSERT_TRUE(w.Open(dir / "c.txt").ok());
  ASSERT_TRUE(w.Write("new content").ok());
  EXPECT_EQ(*ReadFileToString(dir / "c.txt"), "old");
  ASSERT_TRUE(w.WriteAt(0, "N", 1).ok());
  ASSERT_TRUE(w.Commit().ok());
  EXPECT_EQ(*ReadFileToString(dir / "c.txt"), "New content");
}

TEST(AtomicFile, MissingFileIsNotFound) {
  auto r = ReadFileToString("/nonexistent/handdb/file");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_NE(r.status().message().find("/nonexistent/handdb/file"), std::string::npos);
}

// Issue 14 item 7: a FIFO blocked open() forever and /dev/zero grew memory without end; both are
// refused by stat() before anything opens them. Item 8: the other one-line reasons.
TEST(AtomicFile, ReadRefusesWhatIsNotARegularFile) {
  const auto dir = testing::TempDir("read_special");
  const auto fifo = dir / "fifo.json";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  const auto zero = dir / "zero.json";
  std::filesystem::create_symlink("/dev/zero", zero);
  for (const auto& path : {fifo, zero}) {
    auto r = ReadFileToString(path);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kIoError);
    EXPECT_EQ(r.status().message(), path.string() + ": not a regular file");
  }
  auto d = ReadFileToString(dir);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.status().message(), dir.string() + ": is a directory, expected a file");

  const auto loop = dir / "loop";
  std::filesystem::create_symlink(loop, loop);
  auto l = ReadFileToString(loop);
  ASSERT_FALSE(l.ok());
  EXPECT_EQ(l.status().message(),
            loop.string() + ": too many levels of symbolic links (a symlink loop?)");
}

TEST(AtomicFile, ReadRefusesAFileLargerThanTheLimit) {
  const auto dir = testing::TempDir("read_limit");
  ASSERT_TRUE(WriteFileAtomic(dir / "f", "0123456789").ok());
  EXPECT_TRUE(ReadFileToString(dir / "f", 10).ok());
  auto r = ReadFileToString(dir / "f", 9);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(),
            (dir / "f").string() + ": 10 bytes, more than the 9 allowed for this kind of file");
}

}  // namespace
}  // namespace handdb
