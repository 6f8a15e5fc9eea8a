#include "base/atomic_file.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace handdb
