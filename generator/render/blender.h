// The one Blender launcher, for database renders (render_driver.h) and test-set renders
// (generator/testset/testset.h): finds the executable and the entry-point script, builds the
// command line `blender -b --factory-startup -noaudio -t 1 -P SCRIPT -- ARGS...`
// (docs/conventions.md "Blender entry point") and starts it through base/subprocess.h.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "base/status.h"
#include "base/subprocess.h"

namespace handdb {

// The Blender executable to use (`requested`, $HANDDB_BLENDER, `blender` on PATH); kNotFound
// otherwise.
Result<std::filesystem::path> FindBlender(const std::filesystem::path& requested);

class BlenderLauncher {
 public:
  // `blender` and `scripts_dir` as in the render options (empty: FindBlender's search, and
  // $HANDDB_SCRIPTS_DIR, else RepoRoot()/blender_scripts); kNotFound when either the executable
  // or SCRIPTS_DIR/`script` is missing.
  static Result<BlenderLauncher> Find(const std::filesystem::path& blender,
                                      const std::filesystem::path& scripts_dir,
                                      const std::string& script);

  // The full command line for one worker (each worker uses one thread: `-t 1`).
  std::vector<std::string> Argv(const std::vector<std::string>& script_args) const;
  // Starts one worker in its own process group, its output appended to `log`.
  Result<Subprocess> Spawn(const std::vector<std::string>& script_args,
                           const std::filesystem::path& log) const;
  // Runs one worker to completion (options.log, retries, stop flags as base/subprocess.h).
  Result<RunResult> Run(const std::vector<std::string>& script_args,
                        const RunOptions& options) const;

 private:
  std::filesystem::path blender_;
  std::filesystem::path script_;
};

}  // namespace handdb
