#include "base/directory_lock.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <utility>

#include "base/testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

// A second writer is refused at once, with one line naming the directory.
TEST(DirectoryLock, SecondWriterIsRefusedUntilTheFirstLetsGo) {
  const fs::path dir = testing::TempDir("dirlock");
  {
    auto first = DirectoryLock::Acquire(dir);
    ASSERT_TRUE(first.ok()) << first.status().message();
    // flock belongs to the open file description: a second open, even in this process, conflicts.
    auto second = DirectoryLock::Acquire(dir);
    ASSERT_FALSE(second.ok());
    EXPECT_EQ(second.status().code(), StatusCode::kIoError);
    EXPECT_EQ(second.status().message(),
              dir.string() +
                  ": another handdb process is writing here (its lock is held); wait for it to "
                  "finish or use another directory");
    // A child process (fork + exec would close it too: O_CLOEXEC) is refused as well.
    const pid_t pid = ::fork();
    if (pid == 0) _exit(DirectoryLock::Acquire(dir).ok() ? 0 : 7);
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    EXPECT_EQ(WEXITSTATUS(status), 7);
    DirectoryLock moved = std::move(*first);  // moving keeps it held
    EXPECT_FALSE(DirectoryLock::Acquire(dir).ok());
  }
  // Released on destruction.
  EXPECT_TRUE(DirectoryLock::Acquire(dir).ok());
  EXPECT_EQ(DirectoryLock::Acquire(dir / "missing").status().code(), StatusCode::kIoError);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace handdb
