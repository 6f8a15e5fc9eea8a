// handdb index DB: builds the search index of a database (query/index/view_index.h,
// docs/index.md) and lists it in the manifest.
#include <xxhash.h>

#include <CLI/CLI.hpp>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "base/atomic_file.h"
#include "base/directory_lock.h"
#include "base/hex.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "format/manifest.h"
#include "query/database.h"
#include "query/index/view_index.h"

namespace handdb::cli {
namespace fs = std::filesystem;

Status WriteDatabaseIndex(const fs::path& db_dir,
                          const IndexBuildOptions& options,
                          bool print_summary,
                          const char* cmd) {
  auto db = Database::Open(db_dir);
  if (!db.ok()) return db.status();
  auto index = ViewIndex::Build(*db, options);
  if (!index.ok()) return index.status();
  const std::string bytes = index->Serialize();
  const std::string sum = Hex64(XXH3_64bits(bytes.data(), bytes.size()));
  // A new name per content: a reader holding the previous manifest still finds its own index.
  const std::string file = "index-" + sum + ".hdbi";
  const fs::path path = db_dir / file;
  if (Status s = WriteFileAtomic(path, bytes); !s.ok()) return s;

  Manifest manifest = db->manifest();
  const std::optional<ManifestIndex> previous = manifest.index;
  manifest.index = ManifestIndex{file,
                                 kIndexKind,
                                 bytes.size(),
                                 sum,
                                 {{"dims", index->dims()},
                                  {"nlist", index->nlist()},
                                  {"train_views", options.train_views},
                                  {"cell_px", options.grid.cell_units / 16},
                                  {"grid_side", options.grid.side}}};
  if (Status s = WriteManifest(db_dir, manifest); !s.ok()) return s;
  if (previous && previous->file != file) {
    std::error_code ec;
    fs::remove(db_dir / previous->file, ec);  // no longer listed; best effort
  }
  if (print_summary) {
    std::printf("%s: %s: %zu views x %u rolls, %d dims, %d lists, %" PRIu64
                " bytes (%.2f per canonical view, %.3f per virtual view) in %.1f s -> %s\n",
                cmd,
                db_dir.c_str(),
                db->num_views(),
                db->num_rolls(),
                index->dims(),
                index->nlist(),
                static_cast<uint64_t>(bytes.size()),
                static_cast<double>(bytes.size()) / static_cast<double>(db->num_views()),
                static_cast<double>(bytes.size()) / static_cast<double>(db->num_virtual_views()),
                index->build_seconds(),
                path.c_str());
  }
  return Status();
}

int RunIndex(int argc, char** argv) {
  CLI::App app(
      "Build the search index of a database for indexed search (handdb query --search indexed, "
      "the default once an index exists): an approximate chamfer embedding of every view, "
      "projected by a query-whitened PCA, in a FAISS IVF index, written as "
      "DB/index-<checksum>.hdbi and listed in the manifest "
      "(docs/index.md). Deterministic: the same database and options give the same file.",
      "handdb index");
  std::string db_dir;
  IndexBuildOptions options;
  bool quiet = false;
  app.add_option("DB", db_dir, "database directory (manifest.json + shards)")->required();
  int cell_px = options.grid.cell_units / 16;
  app.add_option("--dims", options.dims, "PCA dimensions of the embedding")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--cell-px", cell_px, "embedding grid: cell side in px")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  app.add_option("--grid-side", options.grid.side, "embedding grid: cells per side (odd)")
      ->capture_default_str();
  app.add_option("--nlist", options.nlist, "IVF lists (0: 4 sqrt(views))")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option(
         "--train-views", options.train_views, "views sampled evenly for the PCA and the k-means")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--threads,-j", options.num_threads, "worker threads (-1: all cores)")
      ->capture_default_str();
  app.add_flag("--quiet,-q", quiet, "no progress line and no summary");
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  if (options.num_threads == 0 || options.num_threads < -1) {
    std::fprintf(stderr, "handdb index: --threads must be -1 or >= 1\n");
    return kExitUsage;
  }
  options.progress = !quiet;
  options.grid.cell_units = 16 * cell_px;
  if (std::string error; !options.Check(&error)) {
    std::fprintf(stderr, "handdb index: %s\n", error.c_str());
    return kExitUsage;
  }

  // One writer at a time: generate/convert hold the same lock while they write the manifest.
  auto lock = DirectoryLock::Acquire(db_dir);
  if (!lock.ok()) return Fail("index", lock.status());
  if (Status s = WriteDatabaseIndex(db_dir, options, !quiet, "handdb index"); !s.ok()) {
    return Fail("index", s);
  }
  return kExitOk;
}

}  // namespace handdb::cli
