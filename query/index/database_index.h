// A database's search index on disk: built from the database, written beside its shards as
// DB/index-<xxh3>.hdbi and listed in its manifest. `handdb index`, `handdb generate --index` and
// the final job of `handdb generate --slurm --index` all write it through WriteDatabaseIndex.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "base/status.h"
#include "query/index/view_index.h"

namespace handdb {

// What WriteDatabaseIndex wrote, for a summary line.
struct DatabaseIndexSummary {
  std::filesystem::path path;  // DB/index-<xxh3>.hdbi
  uint64_t bytes = 0;
  int dims = 0;
  int nlist = 0;
  size_t num_views = 0;  // canonical views of the database
  uint32_t num_rolls = 0;
  uint64_t num_virtual_views = 0;
  double build_seconds = 0;
};

// Builds the index of DB_DIR, writes DB/index-<xxh3>.hdbi atomically, lists it in the manifest and
// removes the file it replaces. The caller holds DB_DIR's lock (base/directory_lock.h): the
// manifest is rewritten.
Result<DatabaseIndexSummary> WriteDatabaseIndex(const std::filesystem::path& db_dir,
                                                const IndexBuildOptions& options);

}  // namespace handdb
