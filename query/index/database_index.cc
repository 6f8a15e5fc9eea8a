#include "query/index/database_index.h"

#include <xxhash.h>

#include <optional>
#include <system_error>

#include "base/atomic_file.h"
#include "base/hex.h"
#include "format/manifest.h"
#include "query/database.h"

namespace handdb {
namespace fs = std::filesystem;

Result<DatabaseIndexSummary> WriteDatabaseIndex(const fs::path& db_dir,
                                                const IndexBuildOptions& options) {
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
  DatabaseIndexSummary summary;
  summary.path = path;
  summary.bytes = bytes.size();
  summary.dims = index->dims();
  summary.nlist = index->nlist();
  summary.num_views = db->num_views();
  summary.num_rolls = db->num_rolls();
  summary.num_virtual_views = db->num_virtual_views();
  summary.build_seconds = index->build_seconds();
  return summary;
}

}  // namespace handdb
