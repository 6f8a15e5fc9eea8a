// handdb index DB: builds the search index of a database (query/index/view_index.h,
// docs/index.md) and lists it in the manifest.
#include <CLI/CLI.hpp>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "base/directory_lock.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "query/index/database_index.h"
#include "query/index/view_index.h"

namespace handdb::cli {
namespace fs = std::filesystem;

void PrintIndexSummary(const char* cmd, const fs::path& db_dir, const DatabaseIndexSummary& s) {
  std::printf("%s: %s: %zu views x %u rolls, %d dims, %d lists, %" PRIu64
              " bytes (%.2f per canonical view, %.3f per virtual view) in %.1f s -> %s\n",
              cmd,
              db_dir.c_str(),
              s.num_views,
              s.num_rolls,
              s.dims,
              s.nlist,
              s.bytes,
              static_cast<double>(s.bytes) / static_cast<double>(s.num_views),
              static_cast<double>(s.bytes) / static_cast<double>(s.num_virtual_views),
              s.build_seconds,
              s.path.c_str());
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
  auto written = WriteDatabaseIndex(db_dir, options);
  if (!written.ok()) return Fail("index", written.status());
  if (!quiet) PrintIndexSummary("handdb index", db_dir, *written);
  return kExitOk;
}

}  // namespace handdb::cli
