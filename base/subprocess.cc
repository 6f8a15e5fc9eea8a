#include "base/subprocess.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <fstream>
#include <thread>
#include <utility>

extern char** environ;

namespace handdb {
namespace {

void CloseFd(int* fd) {
  if (*fd >= 0) ::close(*fd);
  *fd = -1;
}

// Spawn with die_with_parent: fork, then in the child (async-signal-safe calls only) its own
// group, PR_SET_PDEATHSIG, default signals, the standard streams and exec. An exec failure comes
// back through a close-on-exec pipe as the child's errno.
Result<pid_t> ForkExec(const std::vector<std::string>& argv,
                       const SpawnOptions& options,
                       int out_fd,
                       int err_fd) {
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const int devnull = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  int log_fd = -1;
  if (out_fd < 0) {
    log_fd = ::open(options.log.c_str(), O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0644);
    if (log_fd < 0) {
      const int e = errno;
      if (devnull >= 0) ::close(devnull);
      return Status(StatusCode::kIoError, options.log.string() + ": " + std::strerror(e));
    }
    out_fd = err_fd = log_fd;
  }
  int report[2] = {-1, -1};
  if (devnull < 0 || ::pipe2(report, O_CLOEXEC) != 0) {
    const int e = errno;
    for (int fd : {devnull, log_fd}) {
      if (fd >= 0) ::close(fd);
    }
    return Status(StatusCode::kIoError, argv[0] + ": cannot start: " + std::strerror(e));
  }
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (options.own_process_group) ::setpgid(0, 0);
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) _exit(127);  // the parent died before the line above
    struct sigaction dfl {};
    dfl.sa_handler = SIG_DFL;
    ::sigaction(SIGINT, &dfl, nullptr);
    ::sigaction(SIGTERM, &dfl, nullptr);
    sigset_t none;
    sigemptyset(&none);
    ::sigprocmask(SIG_SETMASK, &none, nullptr);
    ::dup2(devnull, STDIN_FILENO);
    ::dup2(out_fd, STDOUT_FILENO);
    ::dup2(err_fd, STDERR_FILENO);
    ::execvp(args[0], args.data());
    const int e = errno;
    (void)!::write(report[1], &e, sizeof(e));
    _exit(127);
  }
  const int fork_errno = errno;
  ::close(report[1]);
  for (int fd : {devnull, log_fd}) {
    if (fd >= 0) ::close(fd);
  }
  if (pid < 0) {
    ::close(report[0]);
    return Status(StatusCode::kExternalToolFailed,
                  argv[0] + ": cannot start: " + std::strerror(fork_errno));
  }
  // Also here, so a Kill() right after Spawn reaches the group whichever side runs first.
  if (options.own_process_group) ::setpgid(pid, pid);
  int exec_errno = 0;
  ssize_t n = 0;
  do {
    n = ::read(report[0], &exec_errno, sizeof(exec_errno));
  } while (n < 0 && errno == EINTR);
  ::close(report[0]);
  if (n == static_cast<ssize_t>(sizeof(exec_errno))) {
    int status = 0;
    ::waitpid(pid, &status, 0);
    return Status(exec_errno == ENOENT ? StatusCode::kNotFound : StatusCode::kExternalToolFailed,
                  argv[0] + ": cannot start: " + std::strerror(exec_errno));
  }
  return pid;
}

}  // namespace

Result<Subprocess> Subprocess::Spawn(const std::vector<std::string>& argv,
                                     const SpawnOptions& options) {
  THROW_CHECK(!argv.empty());
  int out_pipe[2] = {-1, -1};
  int err_pipe[2] = {-1, -1};
  const bool pipes = options.log.empty();
  if (pipes && (::pipe2(out_pipe, O_CLOEXEC) != 0 || ::pipe2(err_pipe, O_CLOEXEC) != 0)) {
    const int e = errno;
    for (int fd : {out_pipe[0], out_pipe[1], err_pipe[0], err_pipe[1]}) {
      if (fd >= 0) ::close(fd);
    }
    return Status(StatusCode::kIoError, argv[0] + ": pipe: " + std::strerror(e));
  }
  if (options.die_with_parent) {
    Result<pid_t> pid = ForkExec(argv, options, pipes ? out_pipe[1] : -1, pipes ? err_pipe[1] : -1);
    CloseFd(&out_pipe[1]);
    CloseFd(&err_pipe[1]);
    if (!pid.ok()) {
      CloseFd(&out_pipe[0]);
      CloseFd(&err_pipe[0]);
      return pid.status();
    }
    Subprocess p;
    p.pid_ = *pid;
    p.group_ = options.own_process_group;
    p.out_fd_ = out_pipe[0];
    p.err_fd_ = err_pipe[0];
    return p;
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  if (pipes) {
    posix_spawn_file_actions_adddup2(&actions, out_pipe[1], STDOUT_FILENO);
    posix_spawn_file_actions_adddup2(&actions, err_pipe[1], STDERR_FILENO);
  } else {
    posix_spawn_file_actions_addopen(
        &actions, STDOUT_FILENO, options.log.c_str(), O_WRONLY | O_APPEND | O_CREAT, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  }
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  // The child starts with no signals blocked and SIGINT/SIGTERM at their defaults, whatever
  // handlers or masks the caller has.
  sigset_t none, defaults;
  sigemptyset(&none);
  sigemptyset(&defaults);
  sigaddset(&defaults, SIGINT);
  sigaddset(&defaults, SIGTERM);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setsigdefault(&attr, &defaults);
  short flags = POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF;
  if (options.own_process_group) {
    posix_spawnattr_setpgroup(&attr, 0);
    flags |= POSIX_SPAWN_SETPGROUP;
  }
  posix_spawnattr_setflags(&attr, flags);
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = -1;
  const int rc = ::posix_spawnp(&pid, args[0], &actions, &attr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  CloseFd(&out_pipe[1]);
  CloseFd(&err_pipe[1]);
  if (rc != 0) {
    CloseFd(&out_pipe[0]);
    CloseFd(&err_pipe[0]);
    return Status(rc == ENOENT ? StatusCode::kNotFound : StatusCode::kExternalToolFailed,
                  argv[0] + ": cannot start: " + std::strerror(rc));
  }
  Subprocess p;
  p.pid_ = pid;
  p.group_ = options.own_process_group;
  p.out_fd_ = out_pipe[0];
  p.err_fd_ = err_pipe[0];
  return p;
}

Subprocess::Subprocess(Subprocess&& other) noexcept
    : pid_(std::exchange(other.pid_, -1)),
      group_(other.group_),
      out_fd_(std::exchange(other.out_fd_, -1)),
      err_fd_(std::exchange(other.err_fd_, -1)) {}

Subprocess& Subprocess::operator=(Subprocess&& other) noexcept {
  if (this != &other) {
    CloseFd(&out_fd_);
    CloseFd(&err_fd_);
    pid_ = std::exchange(other.pid_, -1);
    group_ = other.group_;
    out_fd_ = std::exchange(other.out_fd_, -1);
    err_fd_ = std::exchange(other.err_fd_, -1);
  }
  return *this;
}

Subprocess::~Subprocess() {
  CloseFd(&out_fd_);
  CloseFd(&err_fd_);
}

bool Subprocess::TryWait(int* status) {
  if (pid_ < 0) return false;
  const pid_t r = ::waitpid(pid_, status, WNOHANG);
  if (r != pid_) return false;
  pid_ = -1;
  return true;
}

int Subprocess::Wait() {
  int status = 0;
  while (pid_ >= 0 && ::waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
  }
  pid_ = -1;
  return status;
}

void Subprocess::Kill(int sig) const {
  if (pid_ < 0) return;
  ::kill(group_ ? -pid_ : pid_, sig);
}

std::string DescribeExitStatus(int status) {
  if (WIFEXITED(status)) return "exit code " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) {
    const char* name = strsignal(WTERMSIG(status));
    return "killed by signal " + std::to_string(WTERMSIG(status)) +
           (name ? std::string(" (") + name + ")" : "");
  }
  return "status " + std::to_string(status);
}

int ExitCodeOf(int status) {
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return -1;
}

bool RunOptions::Check() const {
  CHECK_OPTION_GE(timeout_seconds, 0.0);
  CHECK_OPTION_GE(max_retries, 0);
  return true;
}

namespace {

// Reads whatever the pipes hold, waiting at most `timeout_ms`; closes a pipe at EOF.
void DrainPipes(int* fds, std::string* const* sinks, int timeout_ms) {
  pollfd p[2];
  int n = 0;
  int which[2];
  for (int i = 0; i < 2; ++i) {
    if (fds[i] < 0) continue;
    p[n] = {fds[i], POLLIN, 0};
    which[n++] = i;
  }
  if (n == 0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
    return;
  }
  if (::poll(p, n, timeout_ms) <= 0) return;
  char buf[4096];
  for (int k = 0; k < n; ++k) {
    if (p[k].revents == 0) continue;
    const int i = which[k];
    const ssize_t got = ::read(fds[i], buf, sizeof(buf));
    if (got > 0) {
      sinks[i]->append(buf, static_cast<size_t>(got));
    } else if (got == 0 || errno != EINTR) {
      CloseFd(&fds[i]);
    }
  }
}

// One attempt: runs until the child has exited and its pipes are closed.
Result<RunResult> RunOnce(const std::vector<std::string>& argv, const RunOptions& options) {
  SpawnOptions spawn;
  spawn.log = options.log;
  spawn.own_process_group = options.own_process_group;
  spawn.die_with_parent = options.die_with_parent;
  auto child = Subprocess::Spawn(argv, spawn);
  if (!child.ok()) return child.status();
  RunResult result;
  int fds[2] = {child->out_fd(), child->err_fd()};
  std::string* sinks[2] = {&result.out, &result.err};
  const auto start = std::chrono::steady_clock::now();
  auto stop_requested = [&] {
    for (const std::atomic<bool>* f : options.stop_flags) {
      if (f != nullptr && f->load()) return true;
    }
    return false;
  };
  bool exited = false;
  std::chrono::steady_clock::time_point kill_deadline{};
  bool killing = false;
  while (!exited || fds[0] >= 0 || fds[1] >= 0) {
    if (!exited && child->TryWait(&result.wait_status)) exited = true;
    if (exited && fds[0] < 0 && fds[1] < 0) break;
    if (!exited && !killing) {
      const double elapsed =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (options.timeout_seconds > 0 && elapsed > options.timeout_seconds) {
        result.timed_out = true;
      } else if (stop_requested()) {
        result.cancelled = true;
      }
      if (result.timed_out || result.cancelled) {
        child->Kill(SIGTERM);
        killing = true;
        kill_deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
      }
    } else if (!exited && std::chrono::steady_clock::now() > kill_deadline) {
      child->Kill(SIGKILL);
    }
    // Once the child is gone, grandchildren may keep the pipes open: stop reading after a kill.
    if (exited && killing) break;
    DrainPipes(fds, sinks, 50);
  }
  CloseFd(&fds[0]);
  CloseFd(&fds[1]);
  result.exit_code = ExitCodeOf(result.wait_status);
  return result;
}

}  // namespace

Result<RunResult> RunSubprocess(const std::vector<std::string>& argv, const RunOptions& options) {
  THROW_CHECK(options.Check());
  for (int attempt = 1;; ++attempt) {
    auto result = RunOnce(argv, options);
    if (!result.ok()) return result.status();
    result->attempts = attempt;
    if (result->ok() || result->cancelled || attempt > options.max_retries) return result;
    if (!options.log.empty()) {
      const std::string why =
          result->timed_out ? "timed out" : DescribeExitStatus(result->wait_status);
      std::ofstream(options.log, std::ios::app)
          << "== " << argv[0] << ": attempt " << attempt << " failed (" << why << "); retrying\n";
    }
  }
}

}  // namespace handdb
