// DB_DIR/manifest.json (schemas/manifest.schema.json): the list of complete shards with their
// counts, sizes and whole-file checksums, the roll count and the label semantics. Written last and
// atomically, so a database directory lists exactly the shards that are complete.
#pragma once

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/shard_writer.h"
#include "format/view.h"

namespace handdb {

constexpr char kManifestFileName[] = "manifest.json";
constexpr char kManifestFormat[] = "handdb-manifest";
constexpr int kManifestVersion = 1;

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
// Writes DB_DIR/manifest.json atomically; refuses (kInvalidArgument) a manifest whose totals do
// not add up or that does not match the schema, so an invalid manifest is never written.
Status WriteManifest(const std::filesystem::path& db_dir, const Manifest& manifest);

}  // namespace handdb
