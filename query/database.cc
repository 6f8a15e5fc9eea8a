#include "query/database.h"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>

#include "base/thread_pool.h"
#include "format/manifest.h"
#include "format/point_codec.h"
#include "format/shard_layout.h"
#include "format/shard_reader.h"

namespace handdb {
namespace {

// Shape names from a shard's metadata JSON: an array of {id, name} under "shapes" (top level,
// or inside "plan" / "config"). Missing or malformed tables give no names (never an error: names
// are a convenience for display).
std::vector<std::string> ShapeNamesFromMetadata(std::string_view metadata) {
  std::vector<std::string> names;
  const nlohmann::json doc = nlohmann::json::parse(metadata, nullptr, /*allow_exceptions=*/false);
  if (!doc.is_object()) return names;
  const nlohmann::json* shapes = nullptr;
  for (const char* parent : {"", "plan", "config"}) {
    const nlohmann::json& obj = *parent ? doc.value(parent, nlohmann::json()) : doc;
    if (obj.is_object() && obj.contains("shapes") && obj["shapes"].is_array()) {
      shapes = *parent ? &doc[parent]["shapes"] : &doc["shapes"];
      break;
    }
  }
  if (shapes == nullptr) return names;
  for (size_t i = 0; i < shapes->size(); ++i) {
    const nlohmann::json& s = (*shapes)[i];
    if (!s.is_object() || !s.contains("name") || !s["name"].is_string()) continue;
    size_t id = i;
    if (s.contains("id") && s["id"].is_number_unsigned()) id = s["id"].get<size_t>();
    if (id > 1000000) continue;
    if (names.size() <= id) names.resize(id + 1);
    names[id] = s["name"].get<std::string>();
  }
  return names;
}

}  // namespace

Database::Database() = default;
Database::~Database() {
  for (size_t v = 0; decoded_points_ != nullptr && v < views_.size(); ++v) {
    delete[] decoded_points_[v].load(std::memory_order_relaxed);
    delete[] decoded_fields_[v].load(std::memory_order_relaxed);
    delete[] search_points_[v].load(std::memory_order_relaxed);
    delete[] search_fields_[v].load(std::memory_order_relaxed);
  }
}

Database::SearchPin::SearchPin(const Database& db) {
  if (db.search_points_ != nullptr) lock_ = std::shared_lock<std::shared_mutex>(*db.search_mutex_);
}
Database::Database(Database&&) noexcept = default;
Database& Database::operator=(Database&&) noexcept = default;

Database Database::FromMemory(std::vector<ViewLabel> labels,
                              std::vector<std::vector<PointQ>> points,
                              uint32_t num_rolls,
                              std::vector<std::string> shape_names) {
  THROW_CHECK_EQ(labels.size(), points.size());
  THROW_CHECK_GE(num_rolls, 1u);
  Database db;
  db.num_rolls_ = num_rolls;
  db.memory_labels_ = std::move(labels);
  db.memory_points_ = std::move(points);
  db.shape_names_ = std::move(shape_names);
  db.views_.resize(db.memory_points_.size());
  for (size_t i = 0; i < db.memory_points_.size(); ++i) {
    db.views_[i].points = db.memory_points_[i].data();
    db.views_[i].num_points = static_cast<uint32_t>(db.memory_points_[i].size());
    db.views_[i].index = static_cast<uint32_t>(i);
    db.num_points_ += db.memory_points_[i].size();
  }
  db.size_bytes_ = db.num_points_ * sizeof(PointQ) + db.memory_labels_.size() * sizeof(ViewLabel);
  return db;
}

Result<Database> Database::Open(const std::filesystem::path& dir,
                                bool verify_checksums,
                                int num_threads,
                                ThreadPool* pool) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    return Status(StatusCode::kNotFound, dir.string() + ": not a database directory");
  }
  return ReadWithStableManifest(dir,
                                [&] { return OpenOnce(dir, verify_checksums, num_threads, pool); });
}

Result<Database> Database::OpenOnce(const std::filesystem::path& dir,
                                    bool verify_checksums,
                                    int num_threads,
                                    ThreadPool* pool) {
  Result<Manifest> manifest = ReadManifest(dir);
  if (!manifest.ok()) return manifest.status();
  Database db;
  db.path_ = dir;
  db.num_rolls_ = manifest->rolls;
  db.manifest_metadata_json_ = manifest->metadata.dump();
  db.shape_names_ = ShapeNamesFromMetadata(db.manifest_metadata_json_);
  for (const ManifestShard& entry : manifest->shards) {
    const std::filesystem::path path = dir / entry.file;
    Result<ShardReader> reader = ShardReader::Open(path);
    if (!reader.ok()) return reader.status();
    if (verify_checksums) HANDDB_RETURN_IF_ERROR(reader->VerifyChecksums());
    const ShardHeaderInfo& header = reader->header();
    if (reader->num_views() != entry.views || header.num_points != entry.points ||
        header.file_size != entry.bytes) {
      return Status(StatusCode::kSizeMismatch,
                    path.string() + ": has " + std::to_string(reader->num_views()) + " views, " +
                        std::to_string(header.num_points) + " points, " +
                        std::to_string(header.file_size) + " bytes; the manifest says " +
                        std::to_string(entry.views) + ", " + std::to_string(entry.points) + ", " +
                        std::to_string(entry.bytes));
    }
    // The one manifest field that sizes the search: a manifest saying 24 rolls over shards made
    // with 48 would make `query` search 24 silently (validate checks every field).
    const nlohmann::json meta =
        nlohmann::json::parse(reader->metadata_json(), nullptr, /*allow_exceptions=*/false);
    if (meta.is_object() && meta.contains("rolls") && meta["rolls"].is_number_unsigned() &&
        meta["rolls"].get<uint64_t>() != manifest->rolls) {
      return Status(StatusCode::kSizeMismatch,
                    path.string() + ": rolls is " + std::to_string(manifest->rolls) +
                        " in the manifest but " + meta["rolls"].dump() +
                        " in the shard's metadata (run 'handdb validate' for every problem)");
    }
    const uint32_t shard_index = static_cast<uint32_t>(db.shards_.size());
    auto owned = std::make_unique<ShardReader>(std::move(reader).value());
    if (db.shape_names_.empty()) db.shape_names_ = ShapeNamesFromMetadata(owned->metadata_json());
    for (size_t i = 0; i < owned->num_views(); ++i) {
      ViewRef ref;
      ref.shard = shard_index;
      ref.index = static_cast<uint32_t>(i);
      ref.num_points = owned->point_count(i);
      ref.coded = owned->coded();
      if (!ref.coded) {
        ref.points = owned->points(i).data();
        ref.coarse_field = owned->coarse_field(i);
      }
      db.views_.push_back(ref);
      db.num_points_ += ref.num_points;
    }
    if (!owned->has_coarse_fields() && !owned->coded()) ++db.shards_without_coarse_fields_;
    // The point spans are copied out; labels are read again only for the top-k of a search.
    owned->ReleaseViewTablePages();
    db.size_bytes_ += header.file_size;
    db.shards_.push_back(std::move(owned));
  }
  if (db.views_.size() >= kInvalidViewId) {
    return Status(StatusCode::kOutOfRange, dir.string() + ": too many views");
  }
  db.manifest_ = std::move(manifest).value();
  const bool any_coded =
      std::any_of(db.shards_.begin(), db.shards_.end(), [](const auto& s) { return s->coded(); });
  if (any_coded) {
    const size_t n = db.views_.size();
    db.decoded_points_ = std::make_unique<std::atomic<PointQ*>[]>(n);
    db.decoded_fields_ = std::make_unique<std::atomic<uint8_t*>[]>(n);
    db.decoded_bytes_ = std::make_unique<std::atomic<uint64_t>>(0);
    db.search_points_ = std::make_unique<std::atomic<PointQ*>[]>(n);
    db.search_fields_ = std::make_unique<std::atomic<uint8_t*>[]>(n);
    db.search_bytes_ = std::make_unique<std::atomic<uint64_t>>(0);
    for (size_t v = 0; v < n; ++v) {
      db.decoded_points_[v].store(nullptr, std::memory_order_relaxed);
      db.decoded_fields_[v].store(nullptr, std::memory_order_relaxed);
      db.search_points_[v].store(nullptr, std::memory_order_relaxed);
      db.search_fields_[v].store(nullptr, std::memory_order_relaxed);
    }
    HANDDB_RETURN_IF_ERROR(db.SummariseViews(ResolveNumThreads(num_threads), pool));
    // That pass read every record and every point code: a search reads only its candidates'.
    for (const auto& shard : db.shards_) {
      shard->ReleaseViewTablePages();
      shard->ReleasePointCodePages();
    }
  }
  return db;
}

// Every view's extent and order for the searcher, without decoding a lattice-mode code: its
// header gives its count, a bound on |x|, |y| (its bounding box) and that it is sorted
// (format/point_codec.h, PeekViewPoints); other codes are decoded (a chunk of views per task,
// one scratch buffer each). A header that cannot be read, or a count that disagrees with the
// record, is an error of Open naming the shard, the view and the byte offset; a code damaged
// past its header is found by the search that decodes it (CodedViewError) or by validate.
Status Database::SummariseViews(int num_threads, ThreadPool* pool) {
  constexpr size_t kChunk = 1024;
  const size_t n = views_.size();
  summaries_.assign(n, PointSummary{});
  auto summarise = [&](size_t k) {
    std::vector<PointQ> scratch;
    const size_t end = std::min(n, (k + 1) * kChunk);
    for (size_t v = k * kChunk; v < end; ++v) {
      const ViewRef& r = views_[v];
      std::span<const PointQ> pts(r.points, r.num_points);
      if (r.coded) {
        ViewPointsExtent extent;
        HANDDB_RETURN_IF_ERROR(shards_[r.shard]->PeekPoints(r.index, &extent));
        if (extent.peeked) {
          summaries_[v].max_abs = extent.max_abs_bound;
          summaries_[v].sorted_by_y = extent.sorted;
          continue;
        }
        HANDDB_RETURN_IF_ERROR(shards_[r.shard]->DecodePoints(r.index, &scratch));
        pts = scratch;
      }
      summaries_[v] = Summarise(pts);
    }
    return Status::Ok();
  };
  return ParallelForStatus((n + kChunk - 1) / kChunk, num_threads, nullptr, summarise, pool);
}

Database::PointSummary Database::Summarise(std::span<const PointQ> points) {
  PointSummary out;
  for (const PointQ& p : points) {
    out.max_abs = std::max(
        {out.max_abs, std::abs(static_cast<int32_t>(p.x)), std::abs(static_cast<int32_t>(p.y))});
  }
  out.sorted_by_y =
      std::is_sorted(points.begin(), points.end(), [](PointQ a, PointQ b) { return a.y < b.y; });
  return out;
}

namespace {

// Decodes into a slot once: the first thread to publish wins, the others free theirs. `decode`
// fills a buffer of `size` elements; `bytes` counts what is kept.
template <typename T, typename Decode>
T* DecodeOnce(std::atomic<T*>& slot, size_t size, std::atomic<uint64_t>& bytes, Decode&& decode) {
  T* p = slot.load(std::memory_order_acquire);
  if (p != nullptr) return p;
  auto fresh = std::make_unique<T[]>(size);
  decode(fresh.get());
  T* expected = nullptr;
  if (slot.compare_exchange_strong(expected, fresh.get(), std::memory_order_acq_rel)) {
    bytes.fetch_add(size * sizeof(T), std::memory_order_relaxed);
    return fresh.release();
  }
  return expected;  // another thread decoded it first
}

}  // namespace

// View v's points or field decoded into one of the two caches (slot v of `points` / `fields`,
// kept bytes counted in `bytes`). A code that does not decode throws CodedViewError
// (Searcher::Search returns its status).
std::span<const PointQ> Database::DecodePointsOnce(view_id_t v,
                                                   std::atomic<PointQ*>* points,
                                                   std::atomic<uint64_t>& bytes) const {
  const ViewRef& r = views_[v];
  if (r.num_points == 0) return {};
  const ShardReader& shard = *shards_[r.shard];
  PointQ* p = DecodeOnce(points[v], r.num_points, bytes, [&](PointQ* out) {
    thread_local std::vector<PointQ> pts;
    const Status s = shard.DecodePoints(r.index, &pts);
    if (!s.ok()) throw CodedViewError(s);
    std::copy(pts.begin(), pts.end(), out);
  });
  return std::span<const PointQ>(p, r.num_points);
}

const uint8_t* Database::DecodeFieldOnce(view_id_t v,
                                         std::atomic<uint8_t*>* fields,
                                         std::atomic<uint64_t>& bytes) const {
  const ViewRef& r = views_[v];
  const ShardReader& shard = *shards_[r.shard];
  return DecodeOnce(fields[v], shard::kCoarseFieldSize, bytes, [&](uint8_t* out) {
    const Status s = shard.DecodeCoarseField(r.index, out);
    if (!s.ok()) throw CodedViewError(s);
  });
}

std::span<const PointQ> Database::DecodedPoints(view_id_t v) const {
  return DecodePointsOnce(v, decoded_points_.get(), *decoded_bytes_);
}

const uint8_t* Database::DecodedField(view_id_t v) const {
  return DecodeFieldOnce(v, decoded_fields_.get(), *decoded_bytes_);
}

std::span<const PointQ> Database::SearchDecodedPoints(view_id_t v) const {
  return DecodePointsOnce(v, search_points_.get(), *search_bytes_);
}

const uint8_t* Database::SearchDecodedField(view_id_t v) const {
  return DecodeFieldOnce(v, search_fields_.get(), *search_bytes_);
}

void Database::TrimSearchCache() const {
  if (search_points_ == nullptr ||
      search_bytes_->load(std::memory_order_relaxed) <= search_budget_) {
    return;
  }
  // Only when no search holds a pin: a running one may be reading any slot.
  std::unique_lock<std::shared_mutex> lock(*search_mutex_, std::try_to_lock);
  if (!lock.owns_lock()) return;
  for (size_t v = 0; v < views_.size(); ++v) {
    delete[] search_points_[v].exchange(nullptr, std::memory_order_relaxed);
    delete[] search_fields_[v].exchange(nullptr, std::memory_order_relaxed);
  }
  search_bytes_->store(0, std::memory_order_relaxed);
}

std::span<const PointQ> Database::ViewPoints(view_id_t v, std::vector<PointQ>* scratch) const {
  THROW_CHECK_LT(v, views_.size());
  const ViewRef& r = views_[v];
  if (!r.coded) return std::span<const PointQ>(r.points, r.num_points);
  PointQ* cached = decoded_points_[v].load(std::memory_order_acquire);
  if (cached != nullptr) return std::span<const PointQ>(cached, r.num_points);
  const Status s = shards_[r.shard]->DecodePoints(r.index, scratch);
  if (!s.ok()) throw CodedViewError(s);
  return *scratch;
}

const uint8_t* Database::ViewCoarseField(view_id_t v, uint8_t* scratch) const {
  THROW_CHECK_LT(v, views_.size());
  const ViewRef& r = views_[v];
  if (!r.coded) return r.coarse_field;
  uint8_t* cached = decoded_fields_[v].load(std::memory_order_acquire);
  if (cached != nullptr) return cached;
  const Status s = shards_[r.shard]->DecodeCoarseField(r.index, scratch);
  if (!s.ok()) throw CodedViewError(s);
  return scratch;
}

void Database::ReleaseCoarseFieldPages() const {
  for (const auto& shard : shards_) shard->ReleaseCoarseFieldPages();
}

ViewLabel Database::label(view_id_t v) const {
  THROW_CHECK_LT(v, views_.size());
  if (shards_.empty()) return memory_labels_[v];
  return shards_[views_[v].shard]->label(views_[v].index);
}

std::string_view Database::shape_name(shape_id_t id) const {
  return id < shape_names_.size() ? std::string_view(shape_names_[id]) : std::string_view();
}

}  // namespace handdb
