// `handdb render`: runs the plan's units through Blender worker processes
// (docs/conventions.md "Blender entry point"), N at a time, resumable, with progress and retries.
//
// Before anything renders: the plan is checked against its schema and for consistency, Blender and
// the hand asset must exist, and the hand-model file must still have the sha256 the plan recorded.
// Units whose RUN_DIR/units/uNNNNN/DONE exists are skipped. Each worker's stdout+stderr go to
// RUN_DIR/logs/uNNNNN.log (appended per attempt). A unit whose worker fails is retried; when it
// still fails the run stops (other workers are killed; their finished views stay) with
// "unit 7 failed after 3 attempts (exit code 1): <last error line>; log: RUN_DIR/logs/u00007.log".
// SIGINT/SIGTERM during the run kill the workers and return kCancelled; finished views stay and a
// rerun continues where it stopped.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "base/status.h"
#include "generator/render/blender.h"

namespace handdb {

struct RenderOptions {
  int jobs = 1;                       // parallel Blender processes (each `-t 1`)
  std::filesystem::path blender;      // empty: $HANDDB_BLENDER, else `blender` on PATH
  std::filesystem::path scripts_dir;  // empty: $HANDDB_SCRIPTS_DIR, else RepoRoot()/blender_scripts
  int max_retries = 2;                // extra attempts for a unit whose worker failed
  int frames_per_process = 0;         // passed as --frames-per-process when > 0
  // A worker whose unit gains no finished render for this long is taken for hung: its process
  // group is SIGKILLed and the attempt fails (retried like a crash). 0: wait forever. A render of
  // the paper's views takes seconds; Blender's start well under a minute.
  double stall_timeout_seconds = 600;
  std::vector<uint32_t> units;                // render only these units (empty: all)
  bool progress = true;                       // progress bar on stderr
  bool handle_signals = true;                 // install SIGINT/SIGTERM handlers for the run
  const std::atomic<bool>* cancel = nullptr;  // optional external cancel flag
  // Called on the driver's thread as each unit completes in this run (e.g. to convert it while
  // the others render). Not called for units skipped as already DONE.
  std::function<void(uint32_t unit)> on_unit_done;
  bool Check() const;
};

struct RenderSummary {
  uint32_t units_total = 0;     // units selected
  uint32_t units_skipped = 0;   // already DONE
  uint32_t units_rendered = 0;  // completed in this run
  uint32_t retries = 0;         // extra attempts used
  uint64_t renders_total = 0;   // renders in the selected units
  uint64_t renders_done = 0;    // .exr files present at the end in the selected units
  double seconds = 0;
};

// Renders `plan_path` into `out_dir` (copying the plan to out_dir/plan.json when it is elsewhere;
// an existing different out_dir/plan.json is an error).
Result<RenderSummary> RenderPlan(const std::filesystem::path& plan_path,
                                 const std::filesystem::path& out_dir,
                                 const RenderOptions& options);

}  // namespace handdb
