#include "base/subprocess.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

namespace handdb {
namespace {

namespace fs = std::filesystem;

fs::path TempLog(const std::string& name) {
  const fs::path p = fs::temp_directory_path() /
                     ("handdb_subprocess_" + name + "_" + std::to_string(::getpid()) + ".log");
  fs::remove(p);
  return p;
}

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(Subprocess, CapturesOutputAndExitCode) {
  auto r = RunSubprocess({"sh", "-c", "echo out; echo err >&2; exit 3"}, RunOptions{});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->out, "out\n");
  EXPECT_EQ(r->err, "err\n");
  EXPECT_EQ(r->exit_code, 3);
  EXPECT_FALSE(r->ok());
  EXPECT_EQ(r->attempts, 1);
  EXPECT_EQ(DescribeExitStatus(r->wait_status), "exit code 3");
}

TEST(Subprocess, StdinIsDevNull) {
  auto r = RunSubprocess({"sh", "-c", "cat; echo done"}, RunOptions{});
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->out, "done\n");
  EXPECT_TRUE(r->ok());
}

TEST(Subprocess, MissingProgramNamesTheCommand) {
  auto r = RunSubprocess({"handdb-no-such-program-xyz"}, RunOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_NE(r.status().message().find("handdb-no-such-program-xyz"), std::string::npos);
}

TEST(Subprocess, AppendsToLogAndRetries) {
  const fs::path log = TempLog("retries");
  RunOptions options;
  options.log = log;
  options.max_retries = 2;
  auto r = RunSubprocess({"sh", "-c", "echo attempt; echo oops >&2; exit 1"}, options);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->attempts, 3);
  EXPECT_EQ(r->exit_code, 1);
  const std::string text = ReadAll(log);
  EXPECT_NE(text.find("attempt\noops\n== sh: attempt 1 failed (exit code 1); retrying\n"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("attempt 2 failed"), std::string::npos);
  EXPECT_EQ(text.find("attempt 3 failed"), std::string::npos);
  fs::remove(log);
}

TEST(Subprocess, TimeoutKillsTheProcessGroup) {
  RunOptions options;
  options.timeout_seconds = 0.3;
  const auto start = std::chrono::steady_clock::now();
  // The grandchild `sleep` is in the same group and dies with it.
  auto r = RunSubprocess({"sh", "-c", "sleep 30 & wait"}, options);
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->timed_out);
  EXPECT_FALSE(r->ok());
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 10.0);
}

TEST(Subprocess, StopFlagCancelsWithoutRetry) {
  std::atomic<bool> stop{false};
  RunOptions options;
  options.stop_flags = {&stop};
  options.max_retries = 3;
  std::thread t([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    stop = true;
  });
  auto r = RunSubprocess({"sleep", "30"}, options);
  t.join();
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->cancelled);
  EXPECT_EQ(r->attempts, 1);
  EXPECT_EQ(r->exit_code, 128 + SIGTERM);
}

TEST(Subprocess, SpawnAndPoll) {
  const fs::path log = TempLog("spawn");
  SpawnOptions options;
  options.log = log;
  auto p = Subprocess::Spawn({"sh", "-c", "echo hi"}, options);
  ASSERT_TRUE(p.ok());
  int status = 0;
  while (!p->TryWait(&status)) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(ExitCodeOf(status), 0);
  EXPECT_EQ(ReadAll(log), "hi\n");
  fs::remove(log);
}

// Whether `pid` is still running (absent or a zombie both count as gone).
bool Running(pid_t pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return false;
  const size_t paren = line.rfind(')');
  return paren != std::string::npos && paren + 2 < line.size() && line[paren + 2] != 'Z';
}

// A helper process spawns `sleep 60` (with or without die_with_parent), reports its pid, then is
// SIGKILLed as `kill -9` of generate would be; returns the sleeper's pid.
pid_t SpawnFromAKilledParent(bool die_with_parent) {
  int fds[2];
  THROW_CHECK(::pipe(fds) == 0);
  const pid_t helper = ::fork();
  if (helper == 0) {
    SpawnOptions options;
    options.die_with_parent = die_with_parent;
    options.log = "/dev/null";
    auto child = Subprocess::Spawn({"sleep", "60"}, options);
    const pid_t pid = child.ok() ? child->pid() : -1;
    (void)!::write(fds[1], &pid, sizeof(pid));
    ::pause();
    _exit(0);
  }
  ::close(fds[1]);
  pid_t sleeper = -1;
  THROW_CHECK(::read(fds[0], &sleeper, sizeof(sleeper)) == sizeof(sleeper));
  ::close(fds[0]);
  ::kill(helper, SIGKILL);
  ::waitpid(helper, nullptr, 0);
  return sleeper;
}

// After kill -9 of generate, its Blender workers (each in its own process group) would keep
// rendering. With die_with_parent they die with it.
TEST(Subprocess, DieWithParentKillsTheChildWhenTheParentIsKilled) {
  const pid_t tied = SpawnFromAKilledParent(true);
  ASSERT_GT(tied, 0);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (Running(tied) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_FALSE(Running(tied));
  // Without it the orphan lives on (what the option fixes); clean it up.
  const pid_t orphan = SpawnFromAKilledParent(false);
  ASSERT_GT(orphan, 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_TRUE(Running(orphan));
  ::kill(orphan, SIGKILL);
}

TEST(Subprocess, DieWithParentSpawnsLikeTheOthers) {
  // Output, exit code, own process group, and the same errors as posix_spawn.
  RunOptions options;
  options.die_with_parent = true;
  auto r = RunSubprocess({"sh", "-c", "echo out; echo err >&2; exit 3"}, options);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->exit_code, 3);
  EXPECT_EQ(r->out, "out\n");
  EXPECT_EQ(r->err, "err\n");
  options.timeout_seconds = 0.5;
  const auto start = std::chrono::steady_clock::now();
  r = RunSubprocess({"sh", "-c", "sleep 30 & sleep 30"}, options);
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->timed_out);
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
  SpawnOptions spawn;
  spawn.die_with_parent = true;
  auto missing = Subprocess::Spawn({"/no/such/program"}, spawn);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(missing.status().message(),
            "/no/such/program: cannot start: No such file or directory");
  const fs::path log = TempLog("tied");
  spawn.log = log;
  auto p = Subprocess::Spawn({"sh", "-c", "echo hi; echo there >&2"}, spawn);
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(::getpgid(p->pid()), p->pid());
  EXPECT_EQ(ExitCodeOf(p->Wait()), 0);
  EXPECT_EQ(ReadAll(log), "hi\nthere\n");
  fs::remove(log);
}

TEST(Subprocess, OptionsCheck) {
  RunOptions good;
  EXPECT_TRUE(good.Check());
  RunOptions bad;
  bad.max_retries = -1;
  EXPECT_FALSE(bad.Check());
}

}  // namespace
}  // namespace handdb
