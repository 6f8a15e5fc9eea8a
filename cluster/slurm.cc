#include "cluster/slurm.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "base/atomic_file.h"
#include "base/progress.h"
#include "base/subprocess.h"

namespace handdb {
namespace {

bool IsPlainWord(const std::string& s, const char* extra) {
  if (s.empty()) return false;
  for (char c : s) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    std::strchr(extra, c) != nullptr;
    if (!ok) return false;
  }
  return true;
}

// A task's file name is the layout's prefix and its index in this many digits (the array
// script computes the same with printf).
constexpr int kTaskNameDigits = 5;

// The #SBATCH lines shared by all scripts; jobs run in `chdir`.
void AppendCommonDirectives(const std::filesystem::path& chdir,
                            const SlurmOptions& options,
                            std::ostringstream& s) {
  s << "#SBATCH --chdir=" << chdir.string() << "\n";
  s << "#SBATCH --cpus-per-task=" << options.cpus_per_task << "\n";
  if (!options.partition.empty()) s << "#SBATCH --partition=" << options.partition << "\n";
  if (!options.time_limit.empty()) s << "#SBATCH --time=" << options.time_limit << "\n";
  if (!options.mem_per_task.empty()) s << "#SBATCH --mem=" << options.mem_per_task << "\n";
  for (const auto& arg : options.sbatch_args) s << "#SBATCH " << arg << "\n";
}

// Words as a bash array body: 'a' 'b c'.
std::string QuoteWords(const std::vector<std::string>& words) {
  std::string out;
  for (const auto& w : words) out += (out.empty() ? "" : " ") + ShellQuote(w);
  return out;
}

void AppendSetup(const SlurmOptions& options, std::ostringstream& s) {
  if (options.setup.empty()) return;
  s << "# Site setup (--slurm-setup):\n" << options.setup;
  if (options.setup.back() != '\n') s << "\n";
}

void AppendVariables(const std::vector<ScriptVariable>& variables, std::ostringstream& s) {
  for (const auto& v : variables) {
    if (v.is_array) {
      s << v.name << "=(" << QuoteWords(v.words) << ")\n";
    } else {
      THROW_CHECK_EQ(v.words.size(), 1u);
      s << v.name << "=" << ShellQuote(v.words[0]) << "\n";
    }
  }
}

}  // namespace

bool SlurmOptions::Check() const {
  CHECK_OPTION(partition.empty() || IsPlainWord(partition, "_-.,"));
  CHECK_OPTION_GE(max_parallel, 0);
  CHECK_OPTION(time_limit.empty() || IsValidSlurmTime(time_limit));
  CHECK_OPTION_GE(cpus_per_task, 1);
  CHECK_OPTION(mem_per_task.empty() || std::regex_match(mem_per_task, std::regex("[0-9]+[KMGT]?")));
  CHECK_OPTION(IsPlainWord(job_name, "_-."));
  for (const auto& arg : sbatch_args) {
    CHECK_OPTION(arg.size() >= 2 && arg[0] == '-' && arg.find('\n') == std::string::npos);
  }
  CHECK_OPTION_GE(max_array_size, 1u);
  return true;
}

bool IsValidSlurmTime(const std::string& time) {
  if (time == "UNLIMITED" || time == "INFINITE" || time == "unlimited" || time == "infinite") {
    return true;
  }
  static const std::regex kTime(
      "[0-9]+|[0-9]+:[0-9]+|[0-9]+:[0-9]+:[0-9]+|"
      "[0-9]+-[0-9]+|[0-9]+-[0-9]+:[0-9]+|[0-9]+-[0-9]+:[0-9]+:[0-9]+");
  return std::regex_match(time, kTime);
}

std::string FormatArrayRanges(std::span<const uint32_t> ids) {
  std::string out;
  size_t i = 0;
  while (i < ids.size()) {
    size_t j = i;
    while (j + 1 < ids.size() && ids[j + 1] == ids[j] + 1) ++j;
    if (!out.empty()) out += ',';
    out += std::to_string(ids[i]);
    if (j > i) out += '-' + std::to_string(ids[j]);
    i = j + 1;
  }
  return out;
}

std::string ArrayChunk::ArraySpec(int max_parallel) const {
  std::string spec = FormatArrayRanges(indices);
  if (max_parallel > 0) spec += '%' + std::to_string(max_parallel);
  return spec;
}

std::vector<ArrayChunk> PlanArrayChunks(std::vector<uint32_t> units, uint32_t max_array_size) {
  THROW_CHECK_GE(max_array_size, 1u);
  std::sort(units.begin(), units.end());
  units.erase(std::unique(units.begin(), units.end()), units.end());
  std::vector<ArrayChunk> chunks;
  for (uint32_t u : units) {
    const uint32_t base = u - u % max_array_size;
    if (chunks.empty() || chunks.back().base != base) chunks.push_back(ArrayChunk{base, {}});
    chunks.back().indices.push_back(u - base);
  }
  return chunks;
}

std::string SlurmTaskName(const std::string& prefix, uint32_t task) {
  char digits[16];
  std::snprintf(digits, sizeof(digits), "%0*u", kTaskNameDigits, task);
  return prefix + digits;
}

std::filesystem::path SlurmArrayLayout::TaskLog(uint32_t task) const {
  return log_dir() / (TaskName(task) + ".log");
}

std::filesystem::path SlurmArrayLayout::TaskFailedMarker(uint32_t task) const {
  return failed_dir() / TaskName(task);
}

std::string ShellQuote(const std::string& word) {
  std::string out = "'";
  for (char c : word) {
    if (c == '\'') {
      out += "'\\''";
    } else {
      out += c;
    }
  }
  out += "'";
  return out;
}

std::string ArrayScript(const SlurmArrayJob& job, const SlurmOptions& options) {
  THROW_CHECK(options.Check());
  const SlurmArrayLayout& layout = job.layout;
  std::ostringstream s;
  s << "#!/bin/bash\n";
  s << "#SBATCH --job-name=" << options.job_name << job.array_job_suffix << "\n";
  // Anything printed before the task opens its own log (e.g. by Slurm itself) lands here.
  s << "#SBATCH --output=" << (layout.log_dir() / "slurm-%A_%a.out").string() << "\n";
  s << "#SBATCH --open-mode=append\n";
  AppendCommonDirectives(job.chdir, options, s);
  s << "# Generated by `" << job.generated_by << "`; submitted as\n"
    << "#   sbatch --array=INDICES " << layout.array_script().string() << " BASE\n"
    << job.array_comment;
  s << "set -uo pipefail\n";
  AppendVariables(job.array_variables, s);
  s << "LOG_DIR=" << ShellQuote(layout.log_dir().string()) << "\n";
  s << "FAILED_DIR=" << ShellQuote(layout.failed_dir().string()) << "\n";
  s << "task=$(( ${1:-0} + SLURM_ARRAY_TASK_ID ))\n";
  s << "name=$(printf "
    << ShellQuote(layout.task_prefix + "%0" + std::to_string(kTaskNameDigits) + "d")
    << " \"$task\")\n";
  s << R"SH(job="${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}"
exec >>"$LOG_DIR/$name.log" 2>&1
)SH";
  const std::string& noun = job.task_noun;
  s << "echo \"=== " << noun
    << " $task: Slurm task $job on $(hostname) at $(date -u +%Y-%m-%dT%H:%M:%SZ)\"\n";
  s << "fail() {\n";
  s << "  echo \"handdb slurm task: " << noun << " $task failed: $1\"\n";
  s << R"SH(  printf '%s\n' "$1 (Slurm task $job on $(hostname))" >"$FAILED_DIR/$name.tmp.$$" &&
    mv -f "$FAILED_DIR/$name.tmp.$$" "$FAILED_DIR/$name"
  exit 1
}
trap 'fail "killed by SIGTERM (time limit reached or job cancelled)"' TERM
)SH";
  AppendSetup(options, s);
  for (const auto& c : job.task_commands) {
    s << c.line << " ||\n  fail \"exit code $? from " << c.what << "\"\n";
  }
  s << "rm -f \"$FAILED_DIR/$name\"\n";
  s << "echo \"=== " << noun << " $task: done at $(date -u +%Y-%m-%dT%H:%M:%SZ)\"\n";
  return s.str();
}

std::string FinalScript(const SlurmArrayJob& job, const SlurmOptions& options) {
  THROW_CHECK(options.Check());
  std::ostringstream s;
  s << "#!/bin/bash\n";
  s << "#SBATCH --job-name=" << options.job_name << job.final_job_suffix << "\n";
  s << "#SBATCH --output=" << job.layout.final_log().string() << "\n";
  s << "#SBATCH --open-mode=append\n";
  AppendCommonDirectives(job.chdir, options, s);
  s << "# Generated by `" << job.generated_by << "`; runs after every array task succeeded\n"
    << "# (--dependency=afterok): " << job.final_comment << "\n";
  s << "set -uo pipefail\n";
  AppendVariables(job.final_variables, s);
  const std::string& noun = job.final_noun;
  s << "echo \"=== " << noun
    << ": Slurm job $SLURM_JOB_ID on $(hostname) at $(date -u +%Y-%m-%dT%H:%M:%SZ)\"\n";
  AppendSetup(options, s);
  s << job.final_command << "\n";
  s << "rc=$?\n";
  s << "echo \"=== " << noun << ": exit code $rc at $(date -u +%Y-%m-%dT%H:%M:%SZ)\"\n";
  s << "exit $rc\n";
  return s.str();
}

Status WriteJobScripts(const SlurmArrayJob& job, const SlurmOptions& options) {
  const SlurmArrayLayout& layout = job.layout;
  std::error_code ec;
  for (const auto& dir : {layout.dir, layout.log_dir(), layout.failed_dir()}) {
    std::filesystem::create_directories(dir, ec);
    if (ec) return Status(StatusCode::kIoError, dir.string() + ": cannot create: " + ec.message());
  }
  HANDDB_RETURN_IF_ERROR(WriteFileAtomic(layout.array_script(), ArrayScript(job, options)));
  return WriteFileAtomic(layout.final_script(), FinalScript(job, options));
}

// ---- Talking to Slurm ---------------------------------------------------------------------------

Result<CommandOutput> RunCommand(const std::vector<std::string>& argv) {
  THROW_CHECK(!argv.empty());
  RunOptions options;
  options.own_process_group = false;  // sbatch/scontrol share our terminal's Ctrl-C
  auto run = RunSubprocess(argv, options);
  if (!run.ok()) {
    const bool missing = run.status().code() == StatusCode::kNotFound;
    return Status(StatusCode::kExternalToolFailed,
                  run.status().message() + (missing ? " (is Slurm installed and on PATH?)" : ""));
  }
  return CommandOutput{run->exit_code, std::move(run->out), std::move(run->err)};
}

namespace {

std::string FirstLine(const std::string& text) {
  std::string line = text.substr(0, text.find('\n'));
  while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
  return line;
}

std::string Join(const std::vector<std::string>& words) {
  std::string out;
  for (const auto& w : words) {
    if (!out.empty()) out += ' ';
    out += IsPlainWord(w, "_-.,:=/%+@") ? w : ShellQuote(w);
  }
  return out;
}

}  // namespace

Result<std::string> SubmitBatch(const std::vector<std::string>& sbatch_args,
                                const std::filesystem::path& script,
                                const std::vector<std::string>& script_args) {
  std::vector<std::string> argv = {"sbatch", "--parsable"};
  argv.insert(argv.end(), sbatch_args.begin(), sbatch_args.end());
  argv.push_back(script.string());
  argv.insert(argv.end(), script_args.begin(), script_args.end());
  auto run = RunCommand(argv);
  if (!run.ok()) return run.status();
  if (run->exit_code != 0) {
    return Status(StatusCode::kExternalToolFailed,
                  "sbatch " + script.string() + " failed (exit " + std::to_string(run->exit_code) +
                      "): " + FirstLine(run->err));
  }
  // --parsable prints "jobid" or "jobid;cluster".
  std::string id = FirstLine(run->out);
  id = id.substr(0, id.find(';'));
  if (id.empty() || !IsPlainWord(id, "_")) {
    return Status(
        StatusCode::kExternalToolFailed,
        "sbatch " + script.string() + ": unexpected output '" + FirstLine(run->out) + "'");
  }
  return id;
}

Result<uint32_t> QueryMaxArraySize() {
  auto run = RunCommand({"scontrol", "show", "config"});
  if (!run.ok()) return run.status();
  if (run->exit_code != 0) {
    return Status(StatusCode::kExternalToolFailed,
                  "scontrol show config failed: " + FirstLine(run->err));
  }
  static const std::regex kLine("MaxArraySize\\s*=\\s*([0-9]+)");
  std::smatch m;
  if (std::regex_search(run->out, m, kLine)) {
    return static_cast<uint32_t>(std::stoul(m[1].str()));
  }
  return 1001u;  // Slurm's default
}

std::vector<SlurmJobState> ParseScontrolJobs(const std::string& text) {
  std::vector<SlurmJobState> jobs;
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line)) {
    std::map<std::string, std::string> kv;
    std::istringstream words(line);
    std::string word;
    while (words >> word) {
      const size_t eq = word.find('=');
      if (eq == std::string::npos || eq == 0) continue;
      kv.emplace(word.substr(0, eq), word.substr(eq + 1));
    }
    if (!kv.count("JobId")) continue;
    SlurmJobState job;
    job.job_id = kv["JobId"];
    job.array_job_id = kv.count("ArrayJobId") ? kv["ArrayJobId"] : "";
    if (kv.count("ArrayTaskId")) {
      const std::string& t = kv["ArrayTaskId"];
      if (!t.empty() &&
          std::all_of(t.begin(), t.end(), [](char c) { return c >= '0' && c <= '9'; })) {
        job.array_task_id = std::stoll(t);
      }
    }
    job.state = kv["JobState"];
    job.reason = kv["Reason"];
    job.exit_code = kv["ExitCode"];
    job.std_out = kv["StdOut"];
    jobs.push_back(std::move(job));
  }
  return jobs;
}

Result<std::vector<SlurmJobState>> QueryJobs(const std::vector<std::string>& job_ids) {
  std::vector<SlurmJobState> all;
  for (const auto& id : job_ids) {
    auto run = RunCommand({"scontrol", "-o", "show", "job", id});
    if (!run.ok()) return run.status();
    if (run->exit_code != 0) {
      // A job Slurm has forgotten (finished longer than MinJobAge ago) is not an error.
      if (run->err.find("Invalid job id") != std::string::npos) continue;
      return Status(StatusCode::kExternalToolFailed,
                    "scontrol show job " + id + " failed: " + FirstLine(run->err));
    }
    auto jobs = ParseScontrolJobs(run->out);
    all.insert(all.end(), jobs.begin(), jobs.end());
  }
  return all;
}

bool IsFinishedJobState(const std::string& state) {
  static const char* kFinished[] = {"COMPLETED",
                                    "FAILED",
                                    "CANCELLED",
                                    "TIMEOUT",
                                    "NODE_FAIL",
                                    "OUT_OF_MEMORY",
                                    "BOOT_FAIL",
                                    "DEADLINE",
                                    "PREEMPTED",
                                    "SPECIAL_EXIT"};
  for (const char* s : kFinished) {
    if (state == s) return true;
  }
  return false;
}

// ---- Submissions -------------------------------------------------------------------------------

Status WriteSubmissionRecord(const std::filesystem::path& path, const SlurmSubmission& sub) {
  nlohmann::json j;
  j["format"] = "handdb-slurm-jobs";
  j["version"] = 1;
  j["db_dir"] = sub.db_dir;
  j["array_job_ids"] = sub.array_job_ids;
  j["chunk_bases"] = sub.chunk_bases;
  j["final_job_id"] = sub.final_job_id;
  j["units"] = sub.units;
  j["sbatch_commands"] = sub.sbatch_commands;
  return WriteFileAtomic(path, j.dump(2) + "\n");
}

Result<SlurmSubmission> ReadSubmissionRecord(const std::filesystem::path& path) {
  auto text = ReadFileToString(path);
  if (!text.ok()) return text.status();
  try {
    const auto j = nlohmann::json::parse(*text);
    if (j.value("format", "") != "handdb-slurm-jobs") {
      return Status(StatusCode::kSchemaViolation,
                    path.string() + ": not a handdb Slurm job record (format field)");
    }
    SlurmSubmission sub;
    sub.db_dir = j.at("db_dir").get<std::string>();
    sub.array_job_ids = j.at("array_job_ids").get<std::vector<std::string>>();
    sub.chunk_bases = j.at("chunk_bases").get<std::vector<uint32_t>>();
    sub.final_job_id = j.at("final_job_id").get<std::string>();
    sub.units = j.at("units").get<std::vector<uint32_t>>();
    sub.sbatch_commands = j.value("sbatch_commands", std::vector<std::vector<std::string>>{});
    return sub;
  } catch (const nlohmann::json::exception& e) {
    return Status(StatusCode::kBadJson, path.string() + ": " + e.what());
  }
}

Result<SlurmSubmission> SubmitArrayWithFinal(const SlurmArrayLayout& layout,
                                             const std::string& target,
                                             const SlurmOptions& options,
                                             const std::vector<uint32_t>& indices,
                                             bool dry_run) {
  THROW_CHECK(options.Check());
  const std::filesystem::path array_script = layout.array_script();
  const std::filesystem::path final_script = layout.final_script();
  SlurmSubmission sub;
  sub.db_dir = target;
  sub.units = indices;
  std::sort(sub.units.begin(), sub.units.end());
  sub.units.erase(std::unique(sub.units.begin(), sub.units.end()), sub.units.end());
  const auto chunks = PlanArrayChunks(sub.units, options.max_array_size);
  std::vector<std::string> dependencies;
  for (const auto& chunk : chunks) {
    std::vector<std::string> args = {"--array=" + chunk.ArraySpec(options.max_parallel)};
    std::vector<std::string> cmd = {"sbatch", "--parsable"};
    cmd.insert(cmd.end(), args.begin(), args.end());
    cmd.push_back(array_script.string());
    cmd.push_back(std::to_string(chunk.base));
    sub.sbatch_commands.push_back(cmd);
    sub.chunk_bases.push_back(chunk.base);
    if (dry_run) continue;
    auto id = SubmitBatch(args, array_script, {std::to_string(chunk.base)});
    if (!id.ok()) return id.status();
    sub.array_job_ids.push_back(*id);
    dependencies.push_back(*id);
  }
  std::vector<std::string> final_args;
  if (!chunks.empty()) {
    std::string dep = "--dependency=afterok";
    for (const auto& id :
         dry_run ? std::vector<std::string>(chunks.size(), "ARRAY_JOB_ID") : dependencies) {
      dep += ":" + id;
    }
    final_args = {dep, "--kill-on-invalid-dep=yes"};
  }
  std::vector<std::string> cmd = {"sbatch", "--parsable"};
  cmd.insert(cmd.end(), final_args.begin(), final_args.end());
  cmd.push_back(final_script.string());
  sub.sbatch_commands.push_back(cmd);
  if (!dry_run) {
    auto id = SubmitBatch(final_args, final_script, {});
    if (!id.ok()) return id.status();
    sub.final_job_id = *id;
    HANDDB_RETURN_IF_ERROR(WriteSubmissionRecord(layout.jobs_file(), sub));
  }
  return sub;
}

std::string FormatUnitFailure(const UnitFailure& failure) {
  return "unit " + std::to_string(failure.unit) + ": " + failure.reason +
         "; log: " + failure.log.string();
}

std::string FormatCommand(const std::vector<std::string>& argv) { return Join(argv); }

// ---- Waiting and failure reports
// -----------------------------------------------------------------

namespace {

namespace fs = std::filesystem;

// The Slurm state of each array task of a submission, keyed by unit (the last report wins).
std::map<uint32_t, SlurmJobState> TaskStatesByUnit(const SlurmSubmission& sub,
                                                   const std::vector<SlurmJobState>& jobs) {
  std::map<uint32_t, SlurmJobState> by_unit;
  for (size_t c = 0; c < sub.array_job_ids.size() && c < sub.chunk_bases.size(); ++c) {
    for (const auto& j : jobs) {
      if (j.array_job_id == sub.array_job_ids[c] && j.array_task_id >= 0) {
        by_unit[sub.chunk_bases[c] + static_cast<uint32_t>(j.array_task_id)] = j;
      }
    }
  }
  return by_unit;
}

}  // namespace

std::string JoinIds(const std::vector<std::string>& ids, const char* sep) {
  std::string out;
  for (const auto& id : ids) out += (out.empty() ? "" : sep) + id;
  return out;
}

std::vector<std::string> JobIds(const SlurmSubmission& sub) {
  std::vector<std::string> ids = sub.array_job_ids;
  if (!sub.final_job_id.empty()) ids.push_back(sub.final_job_id);
  return ids;
}

Result<std::vector<std::string>> ActiveJobs(const SlurmSubmission& sub,
                                            std::vector<SlurmJobState>* states) {
  auto jobs = QueryJobs(JobIds(sub));
  if (!jobs.ok()) return jobs.status();
  std::set<std::string> active;
  for (const auto& j : *jobs) {
    if (IsFinishedJobState(j.state)) continue;
    active.insert(j.array_job_id.empty() ? j.job_id : j.array_job_id);
  }
  if (states != nullptr) *states = *jobs;
  return std::vector<std::string>(active.begin(), active.end());
}

Result<PreviousSubmission> CheckPreviousSubmission(const fs::path& jobs_file,
                                                   const std::string& of_what) {
  PreviousSubmission previous;
  std::error_code ec;
  if (!fs::exists(jobs_file, ec)) return previous;
  auto sub = ReadSubmissionRecord(jobs_file);
  if (!sub.ok()) return sub.status();
  previous.exists = true;
  previous.sub = std::move(*sub);
  auto active = ActiveJobs(previous.sub, &previous.states);
  if (!active.ok()) return active.status();
  if (!active->empty()) {
    return Status(StatusCode::kInvalidArgument,
                  "Slurm jobs " + JoinIds(*active, ", ") + " of an earlier submission " + of_what +
                      " are still queued or running; wait for them (squeue -j " + JoinIds(*active) +
                      ") or cancel them (scancel " + JoinIds(*active, " ") +
                      ") and run this again");
  }
  return previous;
}

Result<std::vector<SlurmJobState>> WaitForJobs(const SlurmSubmission& sub,
                                               uint64_t num_tasks,
                                               double poll_seconds,
                                               bool show_progress) {
  Progress progress("slurm", num_tasks, show_progress, "tasks");
  std::vector<SlurmJobState> states;
  uint64_t shown = 0;
  while (true) {
    auto active = ActiveJobs(sub, &states);
    if (!active.ok()) return active.status();
    uint64_t finished = 0;
    for (const auto& j : states) {
      if (!j.array_job_id.empty() && j.array_task_id >= 0 && IsFinishedJobState(j.state)) {
        ++finished;
      }
    }
    finished = std::min<uint64_t>(finished, num_tasks);
    if (finished > shown) {
      progress.Add(finished - shown);
      shown = finished;
    }
    if (active->empty()) return states;
    std::this_thread::sleep_for(std::chrono::duration<double>(poll_seconds));
  }
}

std::string FinalJobState(const SlurmSubmission& sub, const std::vector<SlurmJobState>& states) {
  std::string final_state = "unknown";
  for (const auto& j : states) {
    if (j.job_id == sub.final_job_id) final_state = j.state;
  }
  return final_state;
}

std::string ReadTrimmed(const fs::path& path) {
  auto text = ReadFileToString(path);
  if (!text.ok()) return "";
  std::string s = *text;
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  return s;
}

std::vector<UnitFailure> CollectFailures(const SlurmArrayLayout& layout,
                                         const std::string& output,
                                         const SlurmSubmission& sub,
                                         const std::vector<bool>& complete,
                                         const std::vector<SlurmJobState>& jobs) {
  const auto states = TaskStatesByUnit(sub, jobs);
  std::vector<UnitFailure> failures;
  for (uint32_t u : sub.units) {
    if (u < complete.size() && complete[u]) continue;
    UnitFailure f;
    f.unit = u;
    f.log = layout.TaskLog(u);
    const std::string marker = ReadTrimmed(layout.TaskFailedMarker(u));
    const auto it = states.find(u);
    if (it != states.end() && !IsFinishedJobState(it->second.state)) {
      f.reason = "still " + it->second.state;
    } else if (!marker.empty()) {
      f.reason = marker;
      if (it != states.end()) f.reason += " [Slurm: " + it->second.state + "]";
    } else if (it != states.end()) {
      f.reason = "Slurm task " + it->second.job_id + " ended " + it->second.state + " (exit " +
                 it->second.exit_code + ") without a " + output;
    } else {
      f.reason = "no " + output + " written (Slurm no longer reports the task)";
    }
    std::error_code ec;
    if (!fs::exists(f.log, ec)) {
      // The task never reached its own log: Slurm's output file is the place to look.
      f.log = it != states.end() && !it->second.std_out.empty() ? fs::path(it->second.std_out)
                                                                : layout.log_dir();
    }
    failures.push_back(std::move(f));
  }
  return failures;
}

}  // namespace handdb
