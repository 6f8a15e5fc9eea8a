#include "base/atomic_file.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

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

// A FIFO or /dev/zero given as input is refused at once by stat(), before anything opens it: open()
// of a FIFO blocks forever and reading /dev/zero grows memory without end. Also the other reasons.
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

// A device or FIFO as the target was renamed over (as root, `-o /dev/null` replaced /dev/null):
// it is written in place now, and a FIFO without a reader is an error, not a block.
TEST(AtomicFile, DevicesAndFifosAreWrittenInPlaceNotReplaced) {
  auto dir = TempDir("device");
  const auto dev = dir / "null";
  if (::mknod(dev.c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0) {
    ASSERT_TRUE(WriteFileAtomic(dev, "into the device").ok());
    struct stat st {};
    ASSERT_EQ(::stat(dev.c_str(), &st), 0);
    EXPECT_TRUE(S_ISCHR(st.st_mode));
    AtomicFileWriter w;
    ASSERT_TRUE(w.Open(dev).ok());
    EXPECT_TRUE(w.streamed());
    ASSERT_TRUE(w.Write("abc").ok());
    EXPECT_FALSE(w.WriteAt(0, "x", 1).ok());  // a stream cannot be patched
  }
  const auto fifo = dir / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  const Status no_reader = WriteFileAtomic(fifo, "lost");
  EXPECT_EQ(no_reader.message(), fifo.string() + ": a FIFO with no reader");
  const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(reader, 0);
  ASSERT_TRUE(WriteFileAtomic(fifo, "through").ok());
  char buf[16] = {};
  EXPECT_EQ(::read(reader, buf, sizeof buf), 7);
  EXPECT_EQ(std::string(buf), "through");
  ::close(reader);
  struct stat st {};
  ASSERT_EQ(::stat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace handdb
