// A read-only database of canonical views for search: point sets and pose labels, either from a
// database directory (manifest + shards, memory-mapped read-only via ShardReader) or from memory
// (tests, benchmarks). Virtual views are (canonical view, roll) with R rolls (format/view.h).
// All accessors are const and safe from many threads.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <shared_mutex>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "format/manifest.h"
#include "format/view.h"

namespace handdb {

class ThreadPool;

class ShardReader;

// A coded view whose code does not decode (damaged past the header Open reads; `handdb validate`
// decodes every view). Thrown by the accessors that decode; Searcher::Search returns status().
class CodedViewError : public std::runtime_error {
 public:
  explicit CodedViewError(Status status)
      : std::runtime_error(status.ToString()), status_(std::move(status)) {}
  const Status& status() const { return status_; }

 private:
  Status status_;
};

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
  // A coded database's views are summarised on num_threads threads, on `pool` when given
  // (base/thread_pool.h, ParallelFor).
  static Result<Database> Open(const std::filesystem::path& dir,
                               bool verify_checksums = false,
                               int num_threads = -1,
                               ThreadPool* pool = nullptr);

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
  // Canonical (roll 0) points of view v. Inline: the search calls it per pair. Zero-copy from a
  // plain shard; a coded shard's view (docs/format.md section 10) is decoded on its first call
  // and kept for the Database's lifetime (decoded_bytes()), so a search that reads a few
  // thousand candidates holds only those. Safe from many threads.
  std::span<const PointQ> points(view_id_t v) const {
    THROW_CHECK_LT(v, views_.size());
    const ViewRef& r = views_[v];
    if (!r.coded) return std::span<const PointQ>(r.points, r.num_points);
    return DecodedPoints(v);
  }
  // Number of points of view v (no decoding).
  uint32_t point_count(view_id_t v) const {
    THROW_CHECK_LT(v, views_.size());
    return views_[v].num_points;
  }
  // For a pass over every view that should not keep decoded copies (index builds, exact-search
  // preparation, exports): points(v) for a plain view, else decoded into *scratch.
  std::span<const PointQ> ViewPoints(view_id_t v, std::vector<PointQ>* scratch) const;
  ViewLabel label(view_id_t v) const;
  // View v's coarse field (format/coarse_field.h) from its shard's v1.1 section, zero-copy, or
  // decoded from a coded shard's field_codes (and kept, as points() does), or nullptr when that
  // shard has none (v1.0 shards, FromMemory databases).
  const uint8_t* coarse_field(view_id_t v) const {
    THROW_CHECK_LT(v, views_.size());
    if (!views_[v].coded) return views_[v].coarse_field;
    return DecodedField(v);
  }
  // coarse_field(v) without keeping a decoded copy: decoded into scratch (kCoarseFieldSize bytes).
  const uint8_t* ViewCoarseField(view_id_t v, uint8_t* scratch) const;
  // True when a shard is coded; then Open read every view's code header (or decoded it) for its
  // summary, kept here for the searcher's per-view extents (max_abs is then a bound).
  bool coded() const { return !summaries_.empty(); }
  struct PointSummary {
    int32_t max_abs = 0;       // largest |x|, |y| of its points, or a bound on it (PointQ units)
    bool sorted_by_y = false;  // points sorted by y
  };
  const std::vector<PointSummary>& point_summaries() const { return summaries_; }
  // The exact summary of a point set (what Open keeps for a raw-mode coded view, and what the
  // searcher computes for a plain one).
  static PointSummary Summarise(std::span<const PointQ> points);
  // Bytes of decoded points and fields held (0 for a database without coded shards): those kept
  // by points()/coarse_field() plus the searches' cache below.
  uint64_t decoded_bytes() const {
    return (decoded_bytes_ ? decoded_bytes_->load(std::memory_order_relaxed) : 0) +
           (search_bytes_ ? search_bytes_->load(std::memory_order_relaxed) : 0);
  }

  // The searches' own cache of decoded views (a coded database's candidates). Search* read it
  // only while holding a SearchPin; TrimSearchCache() frees it when it holds more than
  // search_cache_budget() bytes and no search holds a pin (else it waits for a later call), so
  // a long-running process does not accumulate every view it ever refined (docs/format.md
  // section 10). Spans from SearchPoints/SearchCoarseField are valid while the pin is held.
  // For a plain database these are points()/coarse_field() and the pin costs nothing.
  class SearchPin {
   public:
    explicit SearchPin(const Database& db);

   private:
    std::shared_lock<std::shared_mutex> lock_;
  };
  std::span<const PointQ> SearchPoints(view_id_t v) const {
    THROW_CHECK_LT(v, views_.size());
    const ViewRef& r = views_[v];
    if (!r.coded) return std::span<const PointQ>(r.points, r.num_points);
    return SearchDecodedPoints(v);
  }
  const uint8_t* SearchCoarseField(view_id_t v) const {
    THROW_CHECK_LT(v, views_.size());
    if (!views_[v].coded) return views_[v].coarse_field;
    return SearchDecodedField(v);
  }
  void TrimSearchCache() const;
  // Default 64 MiB (about 17,000 views' points and fields: the candidates of ~8 indexed queries).
  void set_search_cache_budget(uint64_t bytes) { search_budget_ = bytes; }
  uint64_t search_cache_budget() const { return search_budget_; }
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
  static Result<Database> OpenOnce(const std::filesystem::path& dir,
                                   bool verify_checksums,
                                   int num_threads,
                                   ThreadPool* pool);
  struct ViewRef {
    const PointQ* points = nullptr;  // plain: in the shard's mapping or memory_points_
    uint32_t num_points = 0;
    uint32_t shard = 0;
    uint32_t index = 0;  // inside the shard
    bool coded = false;  // points and field are decoded on demand (DecodedPoints/DecodedField)
    const uint8_t* coarse_field = nullptr;  // in the shard's mapping, if it has the section
  };
  std::span<const PointQ> DecodedPoints(view_id_t v) const;
  const uint8_t* DecodedField(view_id_t v) const;
  std::span<const PointQ> SearchDecodedPoints(view_id_t v) const;
  const uint8_t* SearchDecodedField(view_id_t v) const;
  std::span<const PointQ> DecodePointsOnce(view_id_t v,
                                           std::atomic<PointQ*>* points,
                                           std::atomic<uint64_t>& bytes) const;
  const uint8_t* DecodeFieldOnce(view_id_t v,
                                 std::atomic<uint8_t*>* fields,
                                 std::atomic<uint64_t>& bytes) const;
  Status SummariseViews(int num_threads, ThreadPool* pool);
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
  // Coded shards: per view, the decoded points and field once read (owned, freed by the
  // destructor), and every view's summary.
  std::unique_ptr<std::atomic<PointQ*>[]> decoded_points_;
  std::unique_ptr<std::atomic<uint8_t*>[]> decoded_fields_;
  std::unique_ptr<std::atomic<uint64_t>> decoded_bytes_;
  std::unique_ptr<std::atomic<PointQ*>[]> search_points_;
  std::unique_ptr<std::atomic<uint8_t*>[]> search_fields_;
  std::unique_ptr<std::atomic<uint64_t>> search_bytes_;
  std::unique_ptr<std::shared_mutex> search_mutex_ = std::make_unique<std::shared_mutex>();
  uint64_t search_budget_ = uint64_t{64} << 20;
  std::vector<PointSummary> summaries_;
  // FromMemory storage.
  std::vector<ViewLabel> memory_labels_;
  std::vector<std::vector<PointQ>> memory_points_;
};

}  // namespace handdb
