// The Slurm path of `handdb generate` (docs/cluster.md) and the per-unit worker commands its array
// tasks run (`handdb unit render|convert|finalize|status`, in cli/slurm_commands.cc).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "cli/slurm_cli.h"
#include "generator/convert/converter.h"

namespace handdb::cli {

struct SlurmGenerateRequest {
  std::filesystem::path db_dir;
  std::filesystem::path work_dir;  // RUN_DIR; plan.json is already written there
  std::filesystem::path blender;   // --blender of generate (empty: $HANDDB_BLENDER or PATH)
  ConvertOptions convert;          // what makes a shard complete, checked on the login node
  // The edge flags and --skip-bad of generate as typed: every task's `handdb unit convert` and
  // the final `handdb unit finalize` get them verbatim, so they convert as `convert` does.
  std::vector<std::string> convert_args;
  bool build_index = false;  // --index: the final job also runs `handdb index`
  bool quiet = false;
  bool as_json = false;
};

// `handdb generate CONFIG --out DB --slurm ...` once the plan is written: submits (or, with
// --dry-run, only writes) the array for the units whose shard is not complete plus the final job;
// with --wait, waits for them and reports every failed unit with its log. Returns the exit code.
int RunGenerateOnSlurm(const SlurmGenerateRequest& request, const SlurmFlags& flags);

}  // namespace handdb::cli
