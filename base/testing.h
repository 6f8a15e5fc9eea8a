// Helpers for unit tests only (header-only; no library links it): fresh temporary directories,
// whole-file byte reads and writes, and a shell command's exit code and output.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "base/atomic_file.h"
#include "base/status.h"

namespace handdb::testing {

// The directories TempDir made, removed when the test process that made them exits with every
// test passed. A failure's files stay for a look, and so do all of them with
// HANDDB_KEEP_TEST_DIRS set. A death test's child (another pid) removes nothing.
class TempDirs {
 public:
  static TempDirs& Get() {
    static TempDirs dirs;
    return dirs;
  }
  void Add(const std::filesystem::path& dir) {
    std::lock_guard<std::mutex> lock(mu_);
    dirs_.push_back(dir);
  }
  ~TempDirs() {
    if (::getpid() != pid_ || std::getenv("HANDDB_KEEP_TEST_DIRS") != nullptr) return;
    if (::testing::UnitTest::GetInstance()->Failed()) return;
    std::error_code ignored;
    for (const auto& dir : dirs_) std::filesystem::remove_all(dir, ignored);
  }

 private:
  TempDirs() : pid_(::getpid()) {}
  const pid_t pid_;
  std::mutex mu_;
  std::vector<std::filesystem::path> dirs_;
};

// An empty directory <tmp>/handdb_test_<name>_<pid>, removed first if an earlier run left it, and
// at the end of a passing run (TempDirs).
inline std::filesystem::path TempDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("handdb_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  TempDirs::Get().Add(dir);
  return dir;
}

// The whole file; throws (fails the test) if it cannot be read.
inline std::vector<uint8_t> ReadBytes(const std::filesystem::path& path) {
  auto s = ReadFileToString(path);
  THROW_CHECK_MSG(s.ok(), s.status().ToString());
  return std::vector<uint8_t>(s->begin(), s->end());
}

// Replaces the file atomically; throws (fails the test) on error.
inline void WriteBytes(const std::filesystem::path& path, const std::vector<uint8_t>& bytes) {
  const Status s = WriteFileAtomic(
      path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  THROW_CHECK_MSG(s.ok(), s.ToString());
}

// A command's exit code (-1 when a signal ended it) and what it wrote.
struct CliRun {
  int code = -1;
  std::string out;
  std::string err;
};

// Runs `command` with /bin/sh, its stdout and stderr captured in temporary files (removed).
inline CliRun RunShell(const std::string& command) {
  static std::atomic<int> n{0};
  const std::filesystem::path base =
      std::filesystem::temp_directory_path() /
      ("handdb-run-" + std::to_string(::getpid()) + "-" + std::to_string(n++));
  const std::string out = base.string() + ".out", err = base.string() + ".err";
  const int status = std::system((command + " >" + out + " 2>" + err).c_str());
  CliRun r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  for (auto [path, text] : {std::pair{&out, &r.out}, std::pair{&err, &r.err}}) {
    auto s = ReadFileToString(*path);
    if (s.ok()) *text = std::move(s).value();
    std::error_code ignored;
    std::filesystem::remove(*path, ignored);
  }
  return r;
}

}  // namespace handdb::testing
