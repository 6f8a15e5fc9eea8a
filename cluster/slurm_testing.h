// Test helpers for Slurm job scripts (cluster/slurm_test.cc, tests/slurm_jobs_test.cc): a
// temporary directory, a stand-in for handdb, and an array task run as Slurm would run it.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "cluster/slurm.h"

namespace handdb::testing {

namespace fs = std::filesystem;

class TempDir {
 public:
  TempDir() {
    path_ = fs::temp_directory_path() /
            ("handdb-slurm-test-" + std::to_string(getpid()) + "-" + std::to_string(counter_++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  static inline int counter_ = 0;
  fs::path path_;
};

inline std::string Slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A stand-in for handdb in `dir`: prints its arguments as [a][b]... and exits with $RC (0 unset).
inline fs::path EchoArgsProgram(const fs::path& dir) {
  const fs::path path = dir / "echo-args";
  EXPECT_TRUE(WriteFileAtomic(path, "#!/bin/sh\nprintf '[%s]' \"$@\"; echo; exit ${RC:-0}\n").ok());
  fs::permissions(path, fs::perms::owner_all);
  return path;
}

// Runs array script `script` with argument `base` (the chunk's base) as Slurm runs task `task` of
// array job `job`, with extra environment `env` ("NAME=VALUE"). Returns the exit code (-1: no run).
inline int RunArrayTask(const fs::path& script,
                        const std::string& job,
                        const std::string& base,
                        const std::string& task,
                        const std::vector<std::string>& env = {}) {
  std::vector<std::string> argv = {"env"};
  argv.insert(argv.end(), env.begin(), env.end());
  argv.insert(
      argv.end(),
      {"SLURM_ARRAY_JOB_ID=" + job, "SLURM_ARRAY_TASK_ID=" + task, "bash", script.string(), base});
  auto r = RunCommand(argv);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  return r.ok() ? r->exit_code : -1;
}

}  // namespace handdb::testing
