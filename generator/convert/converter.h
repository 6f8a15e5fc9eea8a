// `handdb convert`: a render directory (docs/conventions.md "Files and directories") becomes a
// database: one shard per render unit plus the manifest (written last, listing exactly the
// complete shards). docs/conversion.md describes the edge rule, the normalisation and the roll
// convention.
//
// Every input of a unit is validated before its shard is written. Without skip_bad, any bad view
// (missing/unreadable/truncated EXR, no label channel, labels out of range, wrong size, hand
// touching the border or empty, sidecar missing or disagreeing with the plan) stops the run
// before anything is written; with skip_bad the view is left out and recorded in the shard
// metadata and the manifest's `skipped`. Resumable and idempotent: a shard already present and
// valid for its unit (checksums, same plan, same options) is kept; shards are byte-identical
// across runs and thread counts. Rewriting a database never takes it away from readers: no file
// the current manifest lists is modified or removed before a manifest that does not list it has
// replaced it (docs/format.md section 8).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "edges/edges.h"
#include "edges/view_conversion.h"
#include "format/view.h"

namespace handdb {

struct ConvertOptions {
  int num_threads = -1;  // -1: all cores
  bool skip_bad = false;
  EdgeOptions edges;
  // Write coded shards (format v1.2, docs/format.md section 10): ~4x smaller, points and fields
  // decoded on read. Part of each shard's conversion key: switching it rewrites every shard.
  bool coded = false;
  bool progress = true;
  // Converted units are kept in memory between the checking pass and the writing pass up to this
  // many bytes; units beyond it are converted again when written (same result, more time).
  uint64_t memory_budget_bytes = uint64_t{2} << 30;
  const std::atomic<bool>* cancel = nullptr;  // optional: stop early with kCancelled
  // Convert only these units (empty: all); the others are neither checked nor touched, and no
  // manifest is written (the per-unit step of a Slurm array task, `handdb unit convert`).
  std::vector<uint32_t> units;
  bool Check() const;
};

struct SkippedView {
  uint32_t render_id = 0;
  uint32_t unit = 0;
  std::string file;    // relative to the render dir, e.g. "units/u00007/r000123.exr"
  std::string reason;  // the Status message
};

struct ConvertSummary {
  uint32_t units_total = 0;
  uint32_t shards_written = 0;
  uint32_t shards_kept = 0;  // already present and valid
  uint64_t views = 0;        // canonical views in the database
  uint64_t points = 0;
  uint64_t bytes = 0;  // total shard bytes
  uint32_t rolls = 0;
  std::vector<SkippedView> skipped;
  double seconds = 0;
};

// Converts RENDER_DIR (plan.json + units/) into DB_DIR (shards + manifest.json). Every unit of
// the plan must be complete (units/uNNNNN/DONE). On a bad view without skip_bad returns the first
// error (in render-id order) with "(and N more bad views)" appended, writing nothing; all bad
// views are also returned in *bad when given.
Result<ConvertSummary> ConvertRenderDir(const std::filesystem::path& render_dir,
                                        const std::filesystem::path& db_dir,
                                        const ConvertOptions& options,
                                        std::vector<SkippedView>* bad = nullptr);

// Per unit of RENDER_DIR's plan: whether DB_DIR already holds its complete shard, i.e. one that
// ConvertRenderDir with these options would keep (present, intact, same inputs and options).
// Renders need not be complete. This is what `handdb generate --slurm` resubmits from.
Result<std::vector<bool>> FindCompleteShards(const std::filesystem::path& render_dir,
                                             const std::filesystem::path& db_dir,
                                             const ConvertOptions& options);

// "shard-00007.hdb"
std::string ShardFileName(uint32_t unit_id);
// "shard-00007.next.hdb": where a rewrite puts the unit's new shard while the current manifest
// lists shard-00007.hdb (docs/format.md section 8).
std::string ShardStagingFileName(uint32_t unit_id);

}  // namespace handdb
