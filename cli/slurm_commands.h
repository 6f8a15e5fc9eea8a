// The Slurm path of `handdb generate` (issue 7) and the per-unit worker commands its array tasks
// run (`handdb unit render|convert|finalize|status`, in cli/slurm_commands.cc).
#pragma once

#include <CLI/CLI.hpp>
#include <filesystem>
#include <string>
#include <vector>

#include "generator/convert/converter.h"

namespace handdb::cli {

// The --slurm options of a command that can run as a Slurm job array.
struct SlurmFlags {
  bool enabled = false;
  std::string partition;
  int max_parallel = 0;
  std::string time;
  std::string mem;
  int cpus_per_task = 1;
  bool dry_run = false;
  bool wait = false;
  double poll_seconds = 10;
  std::filesystem::path setup_file;
  std::vector<std::string> sbatch_args;
  void Add(CLI::App& app);
};

struct SlurmGenerateRequest {
  std::filesystem::path db_dir;
  std::filesystem::path work_dir;  // RUN_DIR; plan.json is already written there
  std::filesystem::path blender;   // --blender of generate (empty: $HANDDB_BLENDER or PATH)
  ConvertOptions convert;          // edges and skip_bad are passed on to every task
  bool quiet = false;
  bool as_json = false;
};

// The `handdb unit convert` arguments that reproduce `edges` and `skip_bad` exactly.
std::vector<std::string> ConvertArgs(const EdgeOptions& edges, bool skip_bad);

// `handdb generate CONFIG --out DB --slurm ...` once the plan is written: submits (or, with
// --dry-run, only writes) the array for the units whose shard is not complete plus the final job;
// with --wait, waits for them and reports every failed unit with its log. Returns the exit code.
int RunGenerateOnSlurm(const SlurmGenerateRequest& request, const SlurmFlags& flags);

}  // namespace handdb::cli
