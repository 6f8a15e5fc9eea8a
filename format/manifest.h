// DB_DIR/manifest.json (schemas/manifest.schema.json): the list of complete shards with their
// counts, sizes and whole-file checksums, the roll count and the label semantics. Written last and
// atomically, so a database directory lists exactly the shards that are complete. A file the
// current manifest lists is never modified or removed (docs/format.md section 8, "Rewriting a
// database"): readers that open the database while a convert rewrites it see the old database or
// the new one, whole.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "base/status.h"
#include "format/shard_writer.h"
#include "format/view.h"

namespace handdb {

constexpr char kManifestFileName[] = "manifest.json";
constexpr char kManifestFormat[] = "handdb-manifest";
constexpr int kManifestVersion = 1;
// Largest roll count R a manifest may give (config.schema.json's "rolls" maximum: 0.1 degree
// steps). Readers size per-roll work by R: a manifest with rolls = 10^8 would make `query` grow to
// 4 GB and die with std::bad_alloc; above this ReadManifest refuses it.
constexpr uint32_t kMaxRolls = 3600;

// A unit's shard is "shard-00007.hdb"; while a convert rewrites a database whose manifest lists
// that name, the new shard is written as "shard-00007.next.hdb" and listed under that name by an
// intermediate manifest until the plain name holds the new bytes (docs/format.md section 8).
constexpr char kShardStagingSuffix[] = ".next.hdb";
// "shard-00007.next.hdb" -> "shard-00007.hdb"; any other name is returned unchanged.
std::string ShardFinalFileName(const std::string& file);
// True for "shard-00007.next.hdb".
bool IsShardStagingFileName(const std::string& file);

// Identity of DB_DIR/manifest.json: a convert replaces it by rename(), so every new manifest is a
// new inode with its own times. All zero when there is none.
struct ManifestStamp {
  uint64_t device = 0;
  uint64_t inode = 0;
  int64_t size = -1;
  int64_t mtime_ns = 0;
  int64_t ctime_ns = 0;
  bool operator==(const ManifestStamp&) const = default;
};
ManifestStamp StampManifest(const std::filesystem::path& db_dir);

// How often ReadWithStableManifest runs `read` at most: each retry means a convert swapped the
// manifest during the read, which happens at most twice per convert.
constexpr int kManifestReadAttempts = 8;

// Runs `read` (which reads DB_DIR/manifest.json and the shards it lists) again while the manifest
// was replaced during it, so what it returns comes from one manifest and that manifest's shards.
// A convert removes a shard only after a manifest that no longer lists it is in place, and a
// reader that opened (mmapped) a shard keeps its bytes after the unlink; a reader that read the
// old manifest but reached a shard too late (gone, or with the new bytes) fails, sees the new
// stamp and starts again from the new manifest.
template <typename F>
auto ReadWithStableManifest(const std::filesystem::path& db_dir, F&& read) -> decltype(read()) {
  for (int attempt = 1;; ++attempt) {
    const ManifestStamp before = StampManifest(db_dir);
    auto result = read();
    if (attempt >= kManifestReadAttempts || StampManifest(db_dir) == before) return result;
  }
}

struct ManifestShard {
  std::string file;  // "shard-00007.hdb", relative to the database directory
  uint64_t views = 0;
  uint64_t points = 0;
  uint64_t bytes = 0;
  std::string xxh3;  // XXH3-64 of the whole file, 16 lowercase hex digits
};

struct ManifestLabelField {
  std::string name;
  std::string unit;
  uint32_t count = 1;  // number of components
  std::string description;
};

struct ManifestSkipped {
  render_id_t render_id = kInvalidRenderId;
  std::string file;    // the render output it came from
  std::string reason;  // e.g. "no hand pixels"
};

// The search index of the database (query/index/view_index.h, docs/index.md), when one was built
// by `handdb index`: a manifest rewritten by convert lists none (the shards changed).
struct ManifestIndex {
  std::string file;  // "index-<xxh3>.hdbi" in the database directory
  std::string kind;  // "chamfer-wpca-ivf"
  uint64_t bytes = 0;
  std::string xxh3;  // XXH3-64 of the whole file, 16 lowercase hex digits
  nlohmann::json options = nlohmann::json::object();  // the build options
  bool operator==(const ManifestIndex&) const = default;
};

struct Manifest {
  int version = kManifestVersion;
  std::string tool_version;
  uint32_t rolls = 1;              // R
  uint64_t num_views = 0;          // canonical views, sum of shards[].views
  uint64_t num_virtual_views = 0;  // num_views * rolls
  std::vector<ManifestShard> shards;
  std::vector<ManifestLabelField> labels = ShardLabelFields();
  nlohmann::json metadata = nlohmann::json::object();  // config, hand model hash, versions ...
  std::vector<ManifestSkipped> skipped;
  std::optional<ManifestIndex> index;

  // The label fields of a view record (docs/format.md), names and units.
  static std::vector<ManifestLabelField> ShardLabelFields();
  // Appends a shard from the writer's summary (file name only) and updates the totals.
  void AddShard(const ShardSummary& summary);
  // Recomputes num_views and num_virtual_views from shards and rolls.
  void UpdateTotals();
};

nlohmann::json ManifestToJson(const Manifest& manifest);
// `what` names the source in messages. Checks the schema and the totals (kSizeMismatch).
Result<Manifest> ManifestFromJson(const nlohmann::json& doc, const std::string& what);

// Reads DB_DIR/manifest.json (schema-checked). kNotFound when absent.
Result<Manifest> ReadManifest(const std::filesystem::path& db_dir);
// What the manifest says against what each listed shard's metadata section records (a manifest
// saying 24 rolls over shards made with 48 would make `query` search 24). Compared,
// shard metadata key -> manifest field: `rolls` -> `rolls`, `tool.version` -> `tool_version`,
// `unit` -> the shard's file name, `generation`, `hand_model`, `labels`, `shapes` ->
// `metadata.<same>`, `conversion.edges` / `conversion.normalisation` -> `metadata.conversion.*`,
// `skipped` -> `skipped[]` (each shard's entries listed, and no entry no shard records). A field
// is compared only where the shard records it; when the manifest does not record it, the first
// shard that does is the reference, so the shards still have to agree with each other.
class ManifestShardCheck {
 public:
  explicit ManifestShardCheck(const Manifest& manifest);
  // One line per disagreement, e.g. "rolls is 24 in the manifest but 48 in the shard's metadata"
  // (the caller prefixes the shard's path). Empty when the shard agrees.
  std::vector<std::string> Check(const ManifestShard& entry, const nlohmann::json& metadata);
  // After the last shard: manifest entries that no shard records (skipped renders).
  std::vector<std::string> Finish() const;

 private:
  using SkippedKey = std::tuple<render_id_t, std::string, std::string>;
  nlohmann::json manifest_json_;  // ManifestToJson(manifest), addressed by JSON pointers
  // For a field the manifest does not record: the first shard's value and that shard's file.
  std::map<std::string, std::pair<nlohmann::json, std::string>> first_;
  std::set<SkippedKey> skipped_listed_;
  std::set<SkippedKey> skipped_recorded_;
  bool shards_record_skipped_ = false;
};

// The manifest's labels[] against the v1.0 view record (Manifest::ShardLabelFields(): names,
// units, counts in order); "" when they agree, else the first difference.
std::string ManifestLabelsMismatch(const Manifest& manifest);

// Writes DB_DIR/manifest.json atomically; refuses (kInvalidArgument) a manifest whose totals do
// not add up or that does not match the schema, so an invalid manifest is never written.
Status WriteManifest(const std::filesystem::path& db_dir, const Manifest& manifest);

}  // namespace handdb
