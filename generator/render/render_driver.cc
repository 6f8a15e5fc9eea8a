#include "generator/render/render_driver.h"

#include <signal.h>
#include <sys/statvfs.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <deque>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "base/atomic_file.h"
#include "base/progress.h"
#include "base/sha256.h"
#include "base/subprocess.h"
#include "generator/hand/hand_model.h"
#include "generator/plan/plan.h"
#include "generator/render/blender.h"

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

// Below this many free bytes the render directory's filesystem counts as full: one render (EXR +
// sidecar) of the paper plan is ~1 MB.
constexpr uint64_t kLowDiskBytes = uint64_t{16} << 20;

// Why a worker failed when the disk is full: Blender then leaves a half-written
// EXR and render.py reports "unreadable EXR header", the real cause only in the log. The log's
// "No space left on device" line, or else the filesystem's free space when nearly none is left;
// "" when neither.
std::string DiskFullCause(const fs::path& dir, const fs::path& log) {
  {
    std::ifstream in(log);
    std::string line;
    while (std::getline(in, line)) {
      if (line.find("No space left on device") == std::string::npos) continue;
      if (line.size() > 160) line = line.substr(0, 157) + "...";
      return "the disk is full (the log says: " + line + ")";
    }
  }
  struct statvfs st {};
  if (::statvfs(dir.c_str(), &st) != 0) return "";
  const uint64_t free_bytes = static_cast<uint64_t>(st.f_bavail) * st.f_frsize;
  if (free_bytes >= kLowDiskBytes) return "";
  return "the disk is full (" + dir.string() + ": " + std::to_string(free_bytes) + " bytes free)";
}

struct Worker {
  uint32_t unit = 0;
  int attempt = 1;  // 1-based
};

struct RunningWorker {
  Worker worker;
  Subprocess process;
  // For RenderOptions::stall_timeout_seconds: when the unit's finished count last grew.
  std::chrono::steady_clock::time_point last_progress;
  uint64_t finished = 0;
  bool stalled = false;  // killed as hung
};

// Everything RenderPlan checks before the first render.
struct RenderInputs {
  std::string plan_bytes;
  Plan plan;
  BlenderLauncher blender;
};

Result<RenderInputs> CheckInputs(const fs::path& plan_path, const RenderOptions& options) {
  Result<std::string> plan_bytes = ReadFileToString(plan_path);
  if (!plan_bytes.ok()) return plan_bytes.status();
  Result<Plan> plan = ReadPlan(plan_path);
  if (!plan.ok()) return plan.status();
  Result<BlenderLauncher> blender =
      BlenderLauncher::Find(options.blender, options.scripts_dir, "render.py");
  if (!blender.ok()) return blender.status();

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
  std::error_code ec;
  if (!fs::is_regular_file(asset, ec)) {
    return Status(StatusCode::kNotFound,
                  asset.string() + ": hand asset not found (named by " + hand_path.string() +
                      "; run scripts/deps.sh)");
  }
  return RenderInputs{
      std::move(plan_bytes).value(), std::move(plan).value(), std::move(blender).value()};
}

// The run directory holds its own copy of the plan (workers read that one) and the logs.
Status PrepareRunDir(const fs::path& plan_path,
                     const std::string& plan_bytes,
                     const fs::path& out_dir) {
  const fs::path run_plan = out_dir / "plan.json";
  std::error_code ec;
  if (!fs::exists(run_plan, ec) || !fs::equivalent(run_plan, plan_path, ec)) {
    if (fs::exists(run_plan, ec)) {
      Result<std::string> existing = ReadFileToString(run_plan);
      if (!existing.ok()) return existing.status();
      if (*existing != plan_bytes) {
        return Status(StatusCode::kInvalidArgument,
                      run_plan.string() +
                          ": the run directory already holds a different plan (use another --out)");
      }
    } else {
      HANDDB_RETURN_IF_ERROR(WriteFileAtomic(run_plan, plan_bytes));
    }
  }
  const fs::path logs = out_dir / "logs";
  fs::create_directories(logs, ec);
  if (ec)
    return Status(StatusCode::kIoError,
                  logs.string() + ": cannot create directory: " + ec.message());
  return Status::Ok();
}

// The selected units that still need rendering, with their finished renders counted (so a
// rerun's progress starts where the last one stopped).
struct WorkList {
  std::vector<uint32_t> selected;
  std::deque<Worker> queue;
  std::map<uint32_t, uint64_t> counted;  // unit -> finished .exr seen so far
  uint64_t to_render = 0;
};

Result<WorkList> SelectUnits(const Plan& plan,
                             const RenderOptions& options,
                             const fs::path& out_dir,
                             RenderSummary* summary) {
  WorkList work;
  work.selected = options.units;
  if (work.selected.empty()) {
    for (const auto& u : plan.units) work.selected.push_back(u.id);
  }
  uint64_t baseline = 0;
  std::error_code ec;
  for (uint32_t id : work.selected) {
    if (id >= plan.units.size()) {
      return Status(StatusCode::kInvalidArgument,
                    "unit " + std::to_string(id) + " not in the plan (it has " +
                        std::to_string(plan.units.size()) + " units)");
    }
    ++summary->units_total;
    summary->renders_total += plan.units[id].renders.size();
    const fs::path unit_dir = out_dir / "units" / UnitDirName(id);
    if (fs::exists(unit_dir / "DONE", ec)) {
      ++summary->units_skipped;
      continue;
    }
    work.queue.push_back(Worker{id, 1});
    work.counted[id] = CountFinishedExr(unit_dir);
    baseline += work.counted[id];
  }
  for (const auto& w : work.queue) work.to_render += plan.units[w.unit].renders.size();
  work.to_render -= std::min(work.to_render, baseline);
  return work;
}

// Runs the queued units `options.jobs` at a time, retrying a failed unit first.
class RenderRun {
 public:
  RenderRun(const RenderInputs& inputs,
            const fs::path& out_dir,
            const RenderOptions& options,
            WorkList* work,
            RenderSummary* summary)
      : inputs_(inputs),
        out_dir_(out_dir),
        options_(options),
        work_(work),
        summary_(summary),
        progress_("render", work->to_render, options.progress && !work->queue.empty(), "renders") {}

  Status Run() {
    while (!work_->queue.empty() || !running_.empty()) {
      if (Cancelled()) {
        const uint32_t done = summary_->units_skipped + summary_->units_rendered;
        return Stop(Status(StatusCode::kCancelled,
                           "interrupted: " + std::to_string(done) + " of " +
                               std::to_string(summary_->units_total) +
                               " units complete; finished views are kept, rerun to continue"));
      }
      HANDDB_RETURN_IF_ERROR(StartWorkers());
      int status = 0;
      if (auto it = ReapOne(&status); it != running_.end()) {
        const Worker w = it->second.worker;
        const bool stalled = it->second.stalled;
        running_.erase(it);
        HANDDB_RETURN_IF_ERROR(Finished(w, status, stalled));
        continue;
      }
      PollProgress();
      KillStalledWorkers();
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    PollProgress();
    progress_.Finish();
    return Status::Ok();
  }

 private:
  bool Cancelled() const {
    return g_signal != 0 || (options_.cancel != nullptr && options_.cancel->load());
  }

  fs::path LogPath(uint32_t unit) const { return out_dir_ / "logs" / (UnitDirName(unit) + ".log"); }

  Status StartWorkers() {
    while (static_cast<int>(running_.size()) < options_.jobs && !work_->queue.empty()) {
      const Worker w = work_->queue.front();
      work_->queue.pop_front();
      std::vector<std::string> args = {"--plan",
                                       (out_dir_ / "plan.json").string(),
                                       "--unit",
                                       std::to_string(w.unit),
                                       "--out",
                                       out_dir_.string()};
      if (options_.frames_per_process > 0) {
        args.push_back("--frames-per-process");
        args.push_back(std::to_string(options_.frames_per_process));
      }
      std::string header = "== handdb render: unit " + std::to_string(w.unit) + " attempt " +
                           std::to_string(w.attempt) + "/" +
                           std::to_string(options_.max_retries + 1) + ":";
      for (const auto& a : inputs_.blender.Argv(args)) header += " " + a;
      const fs::path log = LogPath(w.unit);
      {
        std::ofstream out(log, std::ios::app);
        out << header << "\n";
        if (!out) return Stop(Status(StatusCode::kIoError, log.string() + ": cannot write log"));
      }
      Result<Subprocess> process = inputs_.blender.Spawn(args, log);
      if (!process.ok()) return Stop(process.status());
      const pid_t pid = process->pid();
      running_.emplace(pid,
                       RunningWorker{w,
                                     std::move(process).value(),
                                     std::chrono::steady_clock::now(),
                                     work_->counted[w.unit]});
    }
    return Status::Ok();
  }

  // One of our workers that has exited, if any (never another child of this process, so
  // callers that run their own subprocesses concurrently keep their exit statuses).
  std::map<pid_t, RunningWorker>::iterator ReapOne(int* status) {
    for (auto it = running_.begin(); it != running_.end(); ++it) {
      if (it->second.process.TryWait(status)) return it;
    }
    return running_.end();
  }

  // A hung Blender (no render finished for stall_timeout_seconds) is killed,
  // group and all, and its unit retried, instead of holding the run forever.
  void KillStalledWorkers() {
    if (options_.stall_timeout_seconds <= 0) return;
    const auto now = std::chrono::steady_clock::now();
    for (auto& [pid, r] : running_) {
      const uint64_t finished = work_->counted[r.worker.unit];
      if (finished > r.finished) {
        r.finished = finished;
        r.last_progress = now;
      } else if (!r.stalled && std::chrono::duration<double>(now - r.last_progress).count() >
                                   options_.stall_timeout_seconds) {
        r.process.Kill(SIGKILL);
        r.stalled = true;
      }
    }
  }

  // A worker exited: the unit is done, retried, or the run fails.
  Status Finished(const Worker& w, int status, bool stalled) {
    std::error_code ec;
    const bool done = fs::exists(out_dir_ / "units" / UnitDirName(w.unit) / "DONE", ec);
    if (WIFEXITED(status) && WEXITSTATUS(status) == 0 && done) {
      ++summary_->units_rendered;
      if (options_.on_unit_done) options_.on_unit_done(w.unit);
      return Status::Ok();
    }
    if (Cancelled()) return Status::Ok();  // a worker hit by the same Ctrl-C: reported by Run
    const fs::path log = LogPath(w.unit);
    std::string why = DescribeExitStatus(status);
    if (WIFEXITED(status) && WEXITSTATUS(status) == 0) why = "exit code 0 but no DONE marker";
    if (stalled) {
      std::ostringstream seconds;
      seconds << options_.stall_timeout_seconds;
      why = "no render finished in " + seconds.str() + " s: killed as hung";
    }
    if (w.attempt <= options_.max_retries) {
      std::ofstream(log, std::ios::app)
          << "== handdb render: attempt " << w.attempt << " failed (" << why << "); retrying\n";
      ++summary_->retries;
      work_->queue.push_front(Worker{w.unit, w.attempt + 1});
      return Status::Ok();
    }
    const std::string line = LastErrorLine(log);
    const std::string disk_full = DiskFullCause(out_dir_, log);
    return Stop(Status(StatusCode::kExternalToolFailed,
                       "unit " + std::to_string(w.unit) + " failed after " +
                           std::to_string(w.attempt) + " attempt" + (w.attempt == 1 ? "" : "s") +
                           " (" + why + ")" + (disk_full.empty() ? "" : ": " + disk_full) +
                           (line.empty() ? "" : ": " + line) + "; log: " + log.string()));
  }

  void PollProgress() {
    for (auto& [unit, seen] : work_->counted) {
      const uint64_t now = CountFinishedExr(out_dir_ / "units" / UnitDirName(unit));
      if (now > seen) {
        progress_.Add(now - seen);
        seen = now;
      }
    }
  }

  // Ends the run early with `error`: the other workers are killed, their finished views stay.
  Status Stop(Status error) {
    KillWorkers();
    PollProgress();
    progress_.Finish();
    return error;
  }

  void KillWorkers() {
    for (const auto& [pid, r] : running_) r.process.Kill(SIGTERM);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (!running_.empty()) {
      int status = 0;
      if (auto it = ReapOne(&status); it != running_.end()) {
        running_.erase(it);
        continue;
      }
      if (std::chrono::steady_clock::now() > deadline) {
        for (const auto& [pid, r] : running_) r.process.Kill(SIGKILL);
        for (auto& [pid, r] : running_) r.process.Wait();
        running_.clear();
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }

  const RenderInputs& inputs_;
  const fs::path& out_dir_;
  const RenderOptions& options_;
  WorkList* work_;
  RenderSummary* summary_;
  Progress progress_;
  std::map<pid_t, RunningWorker> running_;
};

}  // namespace

bool RenderOptions::Check() const {
  CHECK_OPTION_GE(jobs, 1);
  CHECK_OPTION_LE(jobs, 256);
  CHECK_OPTION_GE(max_retries, 0);
  CHECK_OPTION_GE(frames_per_process, 0);
  CHECK_OPTION_GE(stall_timeout_seconds, 0.0);
  return true;
}

Result<RenderSummary> RenderPlan(const fs::path& plan_path,
                                 const fs::path& out_dir,
                                 const RenderOptions& options) {
  THROW_CHECK(options.Check());
  const auto start = std::chrono::steady_clock::now();
  Result<RenderInputs> inputs = CheckInputs(plan_path, options);
  if (!inputs.ok()) return inputs.status();
  HANDDB_RETURN_IF_ERROR(PrepareRunDir(plan_path, inputs->plan_bytes, out_dir));
  RenderSummary summary;
  Result<WorkList> work = SelectUnits(inputs->plan, options, out_dir, &summary);
  if (!work.ok()) return work.status();
  {
    SignalScope signals(options.handle_signals);
    RenderRun run(*inputs, out_dir, options, &*work, &summary);
    HANDDB_RETURN_IF_ERROR(run.Run());
  }
  for (uint32_t id : work->selected)
    summary.renders_done += CountFinishedExr(out_dir / "units" / UnitDirName(id));
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace handdb
