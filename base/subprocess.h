// The one way handdb starts another program: posix_spawnp of an argv (no shell), stdin from
// /dev/null, output appended to a log file or captured into strings, optionally in its own
// process group (so the whole tree can be killed and a terminal's Ctrl-C reaches only us), with
// an optional timeout and cancel flags (the group is killed) and retries.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <filesystem>
#include <string>
#include <vector>

#include "base/status.h"

namespace handdb {

struct SpawnOptions {
  // Empty: stdout and stderr go to pipes the caller reads (Subprocess::out_fd/err_fd). Else
  // both are appended to this file.
  std::filesystem::path log;
  bool own_process_group = true;
  // The child is SIGKILLed when this process dies, however it dies (PR_SET_PDEATHSIG; it survives
  // the child's own exec). Without it, a `kill -9` of generate leaves Blender workers, each in its
  // own process group, rendering on. Started with fork + exec instead of
  // posix_spawn, which cannot set it; only async-signal-safe calls run between the two.
  bool die_with_parent = false;
};

// A started child. Movable; the destructor does not wait or kill (call Kill + Wait).
class Subprocess {
 public:
  // "ARGV0: cannot start: <errno text>" when it cannot be started: kNotFound when there is no
  // such program, else kExternalToolFailed.
  static Result<Subprocess> Spawn(const std::vector<std::string>& argv,
                                  const SpawnOptions& options);
  Subprocess(Subprocess&& other) noexcept;
  Subprocess& operator=(Subprocess&& other) noexcept;
  Subprocess(const Subprocess&) = delete;
  Subprocess& operator=(const Subprocess&) = delete;
  ~Subprocess();

  pid_t pid() const { return pid_; }
  int out_fd() const { return out_fd_; }  // -1 when logging to a file
  int err_fd() const { return err_fd_; }
  // Reaps the child if it has exited (its waitpid status in *status); never blocks.
  bool TryWait(int* status);
  int Wait();  // blocks; the waitpid status
  // Sends `sig` to the child's process group (own_process_group) or to the child.
  void Kill(int sig) const;

 private:
  Subprocess() = default;
  pid_t pid_ = -1;
  bool group_ = false;
  int out_fd_ = -1;
  int err_fd_ = -1;
};

// "exit code 3", "killed by signal 9 (Killed)".
std::string DescribeExitStatus(int wait_status);
// WEXITSTATUS for an exit, 128 + signal for a signal.
int ExitCodeOf(int wait_status);

struct RunOptions {
  std::filesystem::path log;  // empty: capture stdout and stderr into RunResult::out / err
  bool own_process_group = true;
  bool die_with_parent = false;  // as SpawnOptions::die_with_parent
  double timeout_seconds = 0;    // > 0: the attempt is killed after this long (timed_out)
  // Polled while the child runs: when any is true the child is killed (SIGTERM, then SIGKILL
  // after 5 s) and the run returns with cancelled set; no retry follows.
  std::vector<const std::atomic<bool>*> stop_flags;
  // Extra attempts after a failed one (non-zero exit, killed, timed out), started at once; each
  // failure is noted in the log as "== ARGV0: attempt N failed (WHY); retrying".
  int max_retries = 0;
  bool Check() const;
};

struct RunResult {
  int exit_code = 0;    // of the last attempt (128 + signal when killed)
  int wait_status = 0;  // raw waitpid status of the last attempt
  bool timed_out = false;
  bool cancelled = false;
  int attempts = 0;
  std::string out;  // captured output of the last attempt (when not logging)
  std::string err;
  bool ok() const { return exit_code == 0 && !timed_out && !cancelled; }
};

// Runs argv to completion (with retries). An error Status only when it cannot be started or the
// log cannot be opened; a failing command is a RunResult with exit_code != 0.
Result<RunResult> RunSubprocess(const std::vector<std::string>& argv, const RunOptions& options);

}  // namespace handdb
