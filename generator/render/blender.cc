#include "generator/render/blender.h"

#include <unistd.h>

#include <cstdlib>
#include <sstream>
#include <system_error>

#include "generator/plan/plan.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

bool IsExecutableFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
}

}  // namespace

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

Result<BlenderLauncher> BlenderLauncher::Find(const fs::path& blender,
                                              const fs::path& scripts_dir,
                                              const std::string& script) {
  Result<fs::path> exe = FindBlender(blender);
  if (!exe.ok()) return exe.status();
  fs::path scripts = scripts_dir;
  if (scripts.empty()) {
    const char* env = std::getenv("HANDDB_SCRIPTS_DIR");
    scripts = (env != nullptr && *env != '\0') ? fs::path(env) : RepoRoot() / "blender_scripts";
  }
  BlenderLauncher launcher;
  launcher.blender_ = *exe;
  launcher.script_ = scripts / script;
  std::error_code ec;
  if (!fs::is_regular_file(launcher.script_, ec)) {
    return Status(StatusCode::kNotFound,
                  launcher.script_.string() +
                      ": Blender script not found (set HANDDB_SCRIPTS_DIR or HANDDB_SOURCE_DIR "
                      "to the handdb source tree)");
  }
  return launcher;
}

std::vector<std::string> BlenderLauncher::Argv(const std::vector<std::string>& script_args) const {
  std::vector<std::string> argv = {blender_.string(),
                                   "-b",
                                   "--factory-startup",
                                   "-noaudio",
                                   "-t",
                                   "1",
                                   "-P",
                                   script_.string(),
                                   "--"};
  argv.insert(argv.end(), script_args.begin(), script_args.end());
  return argv;
}

Result<Subprocess> BlenderLauncher::Spawn(const std::vector<std::string>& script_args,
                                          const fs::path& log) const {
  SpawnOptions options;
  options.log = log;
  options.own_process_group = true;
  // A killed handdb leaves no Blender rendering on.
  options.die_with_parent = true;
  return Subprocess::Spawn(Argv(script_args), options);
}

Result<RunResult> BlenderLauncher::Run(const std::vector<std::string>& script_args,
                                       const RunOptions& options) const {
  RunOptions tied = options;
  tied.die_with_parent = true;
  return RunSubprocess(Argv(script_args), tied);
}

}  // namespace handdb
