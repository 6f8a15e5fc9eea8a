#include "generator/render/render_driver.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "base/atomic_file.h"
#include "base/progress.h"
#include "generator/hand/hand_model.h"
#include "generator/plan/plan.h"
#include "base/sha256.h"

extern char** environ;

namespace handdb {
namespace {

namespace fs = std::filesystem;

volatile sig_atomic_t g_signal = 0;
void OnSignal(int sig) { g_signal = sig; }

// Installs SIGINT/SIGTERM handlers for the lifetime of a run and restores the old ones after.
class SignalScope {
 public:
  explicit SignalScope(bool enabled) : enabled_(enabled) {
    g_signal = 0;
    if (!enabled_) return;
    struct sigaction sa {};
    sa.sa_handler = OnSignal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &old_int_);
    sigaction(SIGTERM, &sa, &old_term_);
  }
  ~SignalScope() {
    if (!enabled_) return;
    sigaction(SIGINT, &old_int_, nullptr);
    sigaction(SIGTERM, &old_term_, nullptr);
  }
  SignalScope(const SignalScope&) = delete;
  SignalScope& operator=(const SignalScope&) = delete;

 private:
  bool enabled_;
  struct sigaction old_int_ {};
  struct sigaction old_term_ {};
};

bool IsExecutableFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
}

// "r000123.exr" (a finished render; temp files have other names).
bool IsFinishedExr(const std::string& name) {
  if (name.size() < 6 || name[0] != 'r' || name.compare(name.size() - 4, 4, ".exr") != 0)
    return false;
  return std::all_of(name.begin() + 1, name.end() - 4, [](char c) { return c >= '0' && c <= '9'; });
}

uint64_t CountFinishedExr(const fs::path& unit_dir) {
  std::error_code ec;
  uint64_t n = 0;
  for (fs::directory_iterator it(unit_dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (IsFinishedExr(it->path().filename().string())) ++n;
  }
  return n;
}

std::string DescribeExit(int status) {
  if (WIFEXITED(status)) return "exit code " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) {
    const char* name = strsignal(WTERMSIG(status));
    return "killed by signal " + std::to_string(WTERMSIG(status)) +
           (name ? std::string(" (") + name + ")" : "");
  }
  return "status " + std::to_string(status);
}

// The worker's own error line ("handdb-render: ...") from its log, else its last non-empty line.
std::string LastErrorLine(const fs::path& log) {
  std::ifstream in(log);
  std::string line, last, last_render;
  while (std::getline(in, line)) {
    if (line.empty() || line.rfind("== handdb render", 0) == 0) continue;
    last = line;
    if (line.find("handdb-render:") != std::string::npos) last_render = line;
  }
  std::string out = last_render.empty() ? last : last_render;
  if (out.size() > 240) out = out.substr(0, 237) + "...";
  return out;
}

struct Worker {
  uint32_t unit = 0;
  int attempt = 1;  // 1-based
  pid_t pid = -1;
};

// Reaps one of our workers that has exited, if any (never another child of this process, so
// callers that run their own subprocesses concurrently keep their exit statuses).
pid_t ReapOne(const std::map<pid_t, Worker>& running, int* status) {
  for (const auto& [pid, w] : running) {
    const pid_t r = ::waitpid(pid, status, WNOHANG);
    if (r == pid) return pid;
  }
  return 0;
}

void KillWorkers(std::map<pid_t, Worker>* running) {
  for (const auto& [pid, w] : *running) ::kill(-pid, SIGTERM);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!running->empty()) {
    int status = 0;
    const pid_t pid = ReapOne(*running, &status);
    if (pid > 0) {
      running->erase(pid);
      continue;
    }
    if (std::chrono::steady_clock::now() > deadline) {
      for (const auto& [p, w] : *running) ::kill(-p, SIGKILL);
      for (const auto& [p, w] : *running) ::waitpid(p, &status, 0);
      running->clear();
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

Result<pid_t> SpawnWorker(const std::vector<std::string>& argv,
                          const fs::path& log,
                          const std::string& header) {
  {
    std::ofstream out(log, std::ios::app);
    out << header << "\n";
    if (!out) return Status(StatusCode::kIoError, log.string() + ": cannot write log");
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(
      &actions, STDOUT_FILENO, log.c_str(), O_WRONLY | O_APPEND | O_CREAT, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  // Own process group: we kill the whole worker tree, and a terminal's Ctrl-C reaches only us.
  posix_spawnattr_setpgroup(&attr, 0);
  sigset_t none, defaults;
  sigemptyset(&none);
  sigemptyset(&defaults);
  sigaddset(&defaults, SIGINT);
  sigaddset(&defaults, SIGTERM);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setsigdefault(&attr, &defaults);
  posix_spawnattr_setflags(&attr,
                           POSIX_SPAWN_SETPGROUP | POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, args[0], &actions, &attr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  if (rc != 0) {
    return Status(StatusCode::kExternalToolFailed,
                  argv[0] + ": cannot start: " + std::strerror(rc));
  }
  return pid;
}

}  // namespace

bool RenderOptions::Check() const {
  CHECK_OPTION_GE(jobs, 1);
  CHECK_OPTION_LE(jobs, 256);
  CHECK_OPTION_GE(max_retries, 0);
  CHECK_OPTION_GE(frames_per_process, 0);
  return true;
}

Result<fs::path> FindBlender(const fs::path& requested) {
  auto check = [](const fs::path& p, const std::string& from) -> Result<fs::path> {
    if (IsExecutableFile(p)) return p;
    return Status(StatusCode::kNotFound,
                  p.string() + ": Blender not found or not executable (" + from + ")");
  };
  if (!requested.empty()) return check(requested, "--blender");
  if (const char* env = std::getenv("HANDDB_BLENDER"); env != nullptr && *env != '\0') {
    return check(env, "$HANDDB_BLENDER");
  }
  if (const char* path = std::getenv("PATH"); path != nullptr) {
    std::stringstream ss(path);
    std::string dir;
    while (std::getline(ss, dir, ':')) {
      if (dir.empty()) continue;
      const fs::path candidate = fs::path(dir) / "blender";
      if (IsExecutableFile(candidate)) return candidate;
    }
  }
  return Status(StatusCode::kNotFound,
                "blender not found on PATH (install Blender 3.4+, or pass --blender PATH / set "
                "HANDDB_BLENDER)");
}

Result<RenderSummary> RenderPlan(const fs::path& plan_path,
                                 const fs::path& out_dir,
                                 const RenderOptions& options) {
  THROW_CHECK(options.Check());
  const auto start = std::chrono::steady_clock::now();

  // 1. Everything is checked before the first render.
  Result<std::string> plan_bytes = ReadFileToString(plan_path);
  if (!plan_bytes.ok()) return plan_bytes.status();
  Result<Plan> plan = ReadPlan(plan_path);
  if (!plan.ok()) return plan.status();

  Result<fs::path> blender = FindBlender(options.blender);
  if (!blender.ok()) return blender.status();

  fs::path scripts = options.scripts_dir;
  if (scripts.empty()) {
    const char* env = std::getenv("HANDDB_SCRIPTS_DIR");
    scripts = (env != nullptr && *env != '\0') ? fs::path(env) : RepoRoot() / "blender_scripts";
  }
  const fs::path render_py = scripts / "render.py";
  std::error_code ec;
  if (!fs::is_regular_file(render_py, ec)) {
    return Status(StatusCode::kNotFound,
                  render_py.string() +
                      ": Blender render script not found (set HANDDB_SCRIPTS_DIR "
                      "or HANDDB_SOURCE_DIR to the handdb source tree)");
  }

  const fs::path hand_path = ResolvePlanPath(plan->hand_model_path);
  Result<HandModel> model = LoadHandModel(hand_path);
  if (!model.ok()) return model.status();
  if (model->sha256 != plan->hand_model_sha256) {
    return Status(StatusCode::kChecksumMismatch,
                  hand_path.string() + ": hand model changed since the plan was made (sha256 " +
                      model->sha256 + ", plan has " + plan->hand_model_sha256 +
                      "); re-run handdb plan");
  }
  const fs::path asset = ResolvePlanPath(model->asset_path);
  if (!fs::is_regular_file(asset, ec)) {
    return Status(StatusCode::kNotFound,
                  asset.string() + ": hand asset not found (named by " + hand_path.string() +
                      "; run scripts/deps.sh)");
  }

  // 2. The run directory holds its own copy of the plan (workers read that one).
  const fs::path run_plan = out_dir / "plan.json";
  if (!fs::exists(run_plan, ec) || !fs::equivalent(run_plan, plan_path, ec)) {
    if (fs::exists(run_plan, ec)) {
      Result<std::string> existing = ReadFileToString(run_plan);
      if (!existing.ok()) return existing.status();
      if (*existing != *plan_bytes) {
        return Status(StatusCode::kInvalidArgument,
                      run_plan.string() +
                          ": the run directory already holds a different plan (use another --out)");
      }
    } else {
      HANDDB_RETURN_IF_ERROR(WriteFileAtomic(run_plan, *plan_bytes));
    }
  }
  const fs::path logs = out_dir / "logs";
  fs::create_directories(logs, ec);
  if (ec)
    return Status(StatusCode::kIoError,
                  logs.string() + ": cannot create directory: " + ec.message());

  // 3. Units to run.
  std::vector<uint32_t> selected = options.units;
  if (selected.empty()) {
    for (const auto& u : plan->units) selected.push_back(u.id);
  }
  RenderSummary summary;
  std::deque<Worker> queue;
  uint64_t baseline = 0;
  std::map<uint32_t, uint64_t> counted;  // unit -> finished .exr seen so far
  for (uint32_t id : selected) {
    if (id >= plan->units.size()) {
      return Status(StatusCode::kInvalidArgument,
                    "unit " + std::to_string(id) + " not in the plan (it has " +
                        std::to_string(plan->units.size()) + " units)");
    }
    ++summary.units_total;
    summary.renders_total += plan->units[id].renders.size();
    const fs::path unit_dir = out_dir / "units" / UnitDirName(id);
    if (fs::exists(unit_dir / "DONE", ec)) {
      ++summary.units_skipped;
      continue;
    }
    queue.push_back(Worker{id, 1, -1});
    counted[id] = CountFinishedExr(unit_dir);
    baseline += counted[id];
  }
  uint64_t to_render = 0;
  for (const auto& w : queue) to_render += plan->units[w.unit].renders.size();
  to_render -= std::min(to_render, baseline);

  SignalScope signals(options.handle_signals);
  Progress progress("render", to_render, options.progress && !queue.empty(), "renders");
  std::map<pid_t, Worker> running;
  auto cancelled = [&] {
    return g_signal != 0 || (options.cancel != nullptr && options.cancel->load());
  };
  auto poll_progress = [&] {
    for (auto& [unit, seen] : counted) {
      const uint64_t now = CountFinishedExr(out_dir / "units" / UnitDirName(unit));
      if (now > seen) {
        progress.Add(now - seen);
        seen = now;
      }
    }
  };
  auto finish = [&](Status error) -> Result<RenderSummary> {
    KillWorkers(&running);
    poll_progress();
    progress.Finish();
    return error;
  };

  while (!queue.empty() || !running.empty()) {
    if (cancelled()) {
      uint32_t done = summary.units_skipped + summary.units_rendered;
      return finish(Status(StatusCode::kCancelled,
                           "interrupted: " + std::to_string(done) + " of " +
                               std::to_string(summary.units_total) +
                               " units complete; finished views are kept, rerun to continue"));
    }
    while (static_cast<int>(running.size()) < options.jobs && !queue.empty()) {
      Worker w = queue.front();
      queue.pop_front();
      std::vector<std::string> argv = {blender->string(),
                                       "-b",
                                       "--factory-startup",
                                       "-noaudio",
                                       "-t",
                                       "1",
                                       "-P",
                                       render_py.string(),
                                       "--",
                                       "--plan",
                                       run_plan.string(),
                                       "--unit",
                                       std::to_string(w.unit),
                                       "--out",
                                       out_dir.string()};
      if (options.frames_per_process > 0) {
        argv.push_back("--frames-per-process");
        argv.push_back(std::to_string(options.frames_per_process));
      }
      std::string header = "== handdb render: unit " + std::to_string(w.unit) + " attempt " +
                           std::to_string(w.attempt) + "/" +
                           std::to_string(options.max_retries + 1) + ":";
      for (const auto& a : argv) header += " " + a;
      Result<pid_t> pid = SpawnWorker(argv, logs / (UnitDirName(w.unit) + ".log"), header);
      if (!pid.ok()) return finish(pid.status());
      w.pid = *pid;
      running.emplace(w.pid, w);
    }
    int status = 0;
    const pid_t pid = ReapOne(running, &status);
    if (pid > 0) {
      auto it = running.find(pid);
      Worker w = it->second;
      running.erase(it);
      const fs::path unit_dir = out_dir / "units" / UnitDirName(w.unit);
      const bool done = fs::exists(unit_dir / "DONE", ec);
      if (WIFEXITED(status) && WEXITSTATUS(status) == 0 && done) {
        ++summary.units_rendered;
        if (options.on_unit_done) options.on_unit_done(w.unit);
        continue;
      }
      if (cancelled()) continue;  // a worker hit by the same Ctrl-C: reported as cancelled above
      const fs::path log = logs / (UnitDirName(w.unit) + ".log");
      std::string why = DescribeExit(status);
      if (WIFEXITED(status) && WEXITSTATUS(status) == 0) why = "exit code 0 but no DONE marker";
      if (w.attempt <= options.max_retries) {
        std::ofstream(log, std::ios::app)
            << "== handdb render: attempt " << w.attempt << " failed (" << why << "); retrying\n";
        ++summary.retries;
        queue.push_front(Worker{w.unit, w.attempt + 1, -1});
        continue;
      }
      std::string line = LastErrorLine(log);
      return finish(Status(StatusCode::kExternalToolFailed,
                           "unit " + std::to_string(w.unit) + " failed after " +
                               std::to_string(w.attempt) + " attempt" +
                               (w.attempt == 1 ? "" : "s") + " (" + why + ")" +
                               (line.empty() ? "" : ": " + line) + "; log: " + log.string()));
    }
    poll_progress();
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  poll_progress();
  progress.Finish();
  for (uint32_t id : selected)
    summary.renders_done += CountFinishedExr(out_dir / "units" / UnitDirName(id));
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace handdb
