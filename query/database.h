// A read-only database of canonical views for search: point sets and pose labels, either from a
// database directory (manifest + shards, memory-mapped read-only via ShardReader) or from memory
// (tests, benchmarks). Virtual views are (canonical view, roll) with R rolls (DESIGN.md section 3).
// All accessors are const and safe from many threads.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "format/manifest.h"
#include "format/view.h"

namespace handdb {

class ShardReader;

class Database {
 public:
  Database();
  ~Database();
  Database(Database&&) noexcept;
  Database& operator=(Database&&) noexcept;
  Database(const Database&) = delete;
  Database& operator=(const Database&) = delete;

  // Opens DB_DIR: reads manifest.json (schema-checked), opens every shard it lists (header,
  // section table, footer and view-table checks; see ShardReader::Open), and checks that the
  // shards' view counts match the manifest. With verify_checksums, also hashes every section.
  // A convert rewriting DB_DIR meanwhile is invisible: the manifest and the shards opened are one
  // consistent database, the old one or the new one (ReadWithStableManifest, format/manifest.h).
  static Result<Database> Open(const std::filesystem::path& dir, bool verify_checksums = false);

  // A database held in memory. labels.size() == points.size(); shape_names indexed by shape id
  // (may be empty).
  static Database FromMemory(std::vector<ViewLabel> labels,
                             std::vector<std::vector<PointQ>> points,
                             uint32_t num_rolls,
                             std::vector<std::string> shape_names = {});

  size_t num_views() const { return views_.size(); }
  uint32_t num_rolls() const { return num_rolls_; }
  uint64_t num_virtual_views() const { return static_cast<uint64_t>(num_views()) * num_rolls_; }
  uint64_t num_points() const { return num_points_; }
  // Canonical (roll 0) points of view v, zero-copy. Inline: the search calls it per pair.
  std::span<const PointQ> points(view_id_t v) const {
    THROW_CHECK_LT(v, views_.size());
    return views_[v].points;
  }
  ViewLabel label(view_id_t v) const;
  // View v's coarse field (format/coarse_field.h) from its shard's v1.1 section, zero-copy, or
  // nullptr when that shard has none (v1.0 shards, FromMemory databases).
  const uint8_t* coarse_field(view_id_t v) const {
    THROW_CHECK_LT(v, views_.size());
    return views_[v].coarse_field;
  }
  // True when every view has one (then the search reads them instead of computing them).
  bool has_coarse_fields() const { return !shards_.empty() && shards_without_coarse_fields_ == 0; }
  size_t shards_without_coarse_fields() const { return shards_without_coarse_fields_; }
  // Drops the coarse-fields sections' mapped pages from the resident set, for a caller that has
  // copied the fields (the Searcher's cell-major copy); coarse_field() still works (the pages
  // fault back in from the page cache).
  void ReleaseCoarseFieldPages() const;
  // Name of a shape id from the metadata's shape table, "" if unknown.
  std::string_view shape_name(shape_id_t id) const;
  // Bytes of the database on disk (sum of shard sizes) or in memory (points + labels).
  uint64_t size_bytes() const { return size_bytes_; }
  const std::filesystem::path& path() const { return path_; }
  // The manifest these shards were opened from (a default one for FromMemory databases), and its
  // `metadata` object as JSON text ("{}"): read options and shard lists from here, not from
  // DB_DIR/manifest.json again, which a convert may have replaced since Open.
  const Manifest& manifest() const { return manifest_; }
  const std::string& manifest_metadata_json() const { return manifest_metadata_json_; }

 private:
  static Result<Database> OpenOnce(const std::filesystem::path& dir, bool verify_checksums);
  struct ViewRef {
    uint32_t shard = 0;
    uint32_t index = 0;  // inside the shard
    std::span<const PointQ> points;
    const uint8_t* coarse_field = nullptr;  // in the shard's mapping, if it has the section
  };
  size_t shards_without_coarse_fields_ = 0;
  std::vector<ViewRef> views_;
  uint32_t num_rolls_ = 1;
  uint64_t num_points_ = 0;
  uint64_t size_bytes_ = 0;
  std::filesystem::path path_;
  std::vector<std::string> shape_names_;
  Manifest manifest_;
  std::string manifest_metadata_json_ = "{}";
  std::vector<std::unique_ptr<ShardReader>> shards_;
  // FromMemory storage.
  std::vector<ViewLabel> memory_labels_;
  std::vector<std::vector<PointQ>> memory_points_;
};

}  // namespace handdb
