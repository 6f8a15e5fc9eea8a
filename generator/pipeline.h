// `handdb generate` as one library call: plan -> render -> convert -> validate -> (index), after
// COLMAP's automatic reconstruction controller. The CLI parses flags into GenerateOptions and
// prints; the stages run here.
//
// The index step is a callable the caller passes (GenerateOptions::index_step): the index is
// query/'s business (query/index/database_index.h), and generator/ ranks beside query/, so it may
// not include it. A caller that links both (the CLI) hands WriteDatabaseIndex in; the pipeline only
// decides when it runs: last, on a database that validated, under the lock this run holds.
//
// Resumable: an existing plan must equal the one the config makes (else the work directory belongs
// to another database), the render driver skips finished units and views, and the converter keeps
// shards that are complete; so rerunning the same call after a kill finishes the work.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "base/directory_lock.h"
#include "base/status.h"
#include "format/validator.h"
#include "generator/convert/converter.h"
#include "generator/render/render_driver.h"

namespace handdb {

struct GenerateOptions {
  std::filesystem::path config_path;  // generation config (schemas/config.schema.json)
  std::filesystem::path db_dir;       // database directory to write
  std::filesystem::path work_dir;     // render directory; empty: DB_DIR/render
  RenderOptions render;               // its progress is set from `progress`
  ConvertOptions convert;             // likewise
  bool progress = true;               // progress displays of the stages
  // Stage 5 when set: builds DB's index (DB's lock is held by this run).
  std::function<Status(const std::filesystem::path& db_dir)> index_step;
  // Called as each stage starts: its number (1-based), the number of stages, its name.
  std::function<void(int stage, int num_stages, const char* name)> on_stage;
  bool Check(std::string* error = nullptr) const;
};

struct GenerateSummary {
  RenderSummary render;
  ConvertSummary convert;
  std::vector<SkippedView> bad;  // bad views the converter found (with skip_bad: left out)
  ValidationReport validation;
};

// One run of the pipeline. Plan() locks DB_DIR and the work directory (held until the pipeline is
// destroyed: a second generate or convert into them is refused with one line) and writes or checks
// the plan; Run() does the rest locally. A Slurm run (cli/) calls Plan() only and submits the rest.
class GeneratePipeline {
 public:
  explicit GeneratePipeline(GenerateOptions options);

  // Stage 1. The plan first, so a bad config leaves no directory behind.
  Status Plan();
  // Stages 2-5 after Plan(). On an error, `summary` holds what was found so far: the bad views of
  // a failed conversion, the problems of a failed validation.
  Status Run(GenerateSummary* summary);

  const GenerateOptions& options() const { return options_; }
  const std::filesystem::path& work_dir() const { return options_.work_dir; }
  std::filesystem::path plan_path() const { return options_.work_dir / "plan.json"; }
  int num_stages() const { return options_.index_step ? 5 : 4; }

 private:
  void Stage(int k, const char* name) const;

  GenerateOptions options_;
  std::vector<DirectoryLock> locks_;
  bool planned_ = false;
};

}  // namespace handdb
