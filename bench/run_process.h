// One child process timed from spawn to reaped, with its CPU time: what the start-up and
// single-photo benches measure. Its own posix_spawn and wait4: base/subprocess.h polls its pipes,
// which would add to a start of a few tens of ms. Header-only (benchmarks are single files).
#pragma once

#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <vector>

extern char** environ;

namespace handdb::bench {

struct Timed {
  double seconds = 0;      // from spawn to reaped
  double cpu_seconds = 0;  // user + system time of the process
  bool ok = false;         // started and exited 0
  long minor_faults = 0;   // page faults served without I/O
};

// Runs argv with stdin from `in` (or /dev/null when empty), stdout into `out` (or discarded when
// empty) and stderr discarded; `env` replaces the environment when not empty.
inline Timed RunTimed(const std::vector<std::string>& argv,
                      const std::string& out,
                      const std::string& in = "",
                      const std::vector<std::string>& env = {}) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(
      &actions, STDIN_FILENO, in.empty() ? "/dev/null" : in.c_str(), O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions,
                                   STDOUT_FILENO,
                                   out.empty() ? "/dev/null" : out.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC,
                                   0644);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, "/dev/null", O_WRONLY, 0);
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  std::vector<char*> envp;
  for (const std::string& e : env) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  const auto t0 = std::chrono::steady_clock::now();
  pid_t pid = 0;
  const int rc = posix_spawn(
      &pid, args[0], &actions, nullptr, args.data(), env.empty() ? environ : envp.data());
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) return {};
  int status = 0;
  rusage usage{};
  if (wait4(pid, &status, 0, &usage) != pid) return {};
  auto seconds = [](const timeval& t) { return static_cast<double>(t.tv_sec) + t.tv_usec * 1e-6; };
  return {std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
          seconds(usage.ru_utime) + seconds(usage.ru_stime),
          WIFEXITED(status) && WEXITSTATUS(status) == 0,
          usage.ru_minflt};
}

}  // namespace handdb::bench
