// Checks shards and database directories completely and reports every problem (file, offset, raw
// values), unlike the reader, which stops at the first. What is checked is listed in
// docs/format.md ("What a validator checks").
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"

namespace handdb {

struct ValidateOptions {
  // Problems listed per file and kind of check; the rest are counted in `suppressed`. 0 = all.
  size_t max_problems_per_check = 20;
  bool verify_checksums = true;
  // Allowed excess over the hand model's joint limits (float rounding of clamped samples), rad.
  double joint_limit_tolerance = 1e-4;
  bool show_progress = false;  // a progress line on stderr for directories
  bool Check() const;
};

struct ValidationProblem {
  StatusCode code = StatusCode::kOk;
  std::string file;
  uint64_t offset = 0;  // byte offset in `file` (0 for file-level problems)
  std::string message;  // one line: "<file>: offset <o>: <problem with raw values>"
};

struct ValidationReport {
  std::vector<ValidationProblem> problems;
  uint64_t suppressed = 0;  // problems beyond max_problems_per_check, counted only
  uint64_t files = 0;       // shard files examined
  uint64_t views = 0;       // views whose labels and points were checked
  uint64_t points = 0;
  bool ok() const { return problems.empty() && suppressed == 0; }
  uint64_t num_problems() const { return problems.size() + suppressed; }
  void Append(ValidationReport other);
};

// One shard held in memory; `name` is used as the file in messages.
ValidationReport ValidateShardBytes(std::span<const uint8_t> bytes,
                                    const std::string& name,
                                    const ValidateOptions& options = {});
// One shard file (memory-mapped).
ValidationReport ValidateShardFile(const std::filesystem::path& path,
                                   const ValidateOptions& options = {});
// A database directory: manifest.json against its schema, every listed shard (present, size,
// whole-file checksum, counts, contents), no unlisted shard-*.hdb files, render ids unique.
// Staging files (shard-00007.next.hdb) that the manifest does not list are a rewrite in progress
// or an interrupted one, not part of the database, and are not checked. Run again while a
// convert replaced the manifest meanwhile (ReadWithStableManifest).
ValidationReport ValidateDatabase(const std::filesystem::path& db_dir,
                                  const ValidateOptions& options = {});
// A shard file or a database directory.
ValidationReport ValidatePath(const std::filesystem::path& path,
                              const ValidateOptions& options = {});

}  // namespace handdb
