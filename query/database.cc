#include "query/database.h"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>

#include "format/manifest.h"
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
Database::~Database() = default;
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
    db.views_[i] = {0, static_cast<uint32_t>(i), db.memory_points_[i]};
    db.num_points_ += db.memory_points_[i].size();
  }
  db.size_bytes_ = db.num_points_ * sizeof(PointQ) + db.memory_labels_.size() * sizeof(ViewLabel);
  return db;
}

Result<Database> Database::Open(const std::filesystem::path& dir, bool verify_checksums) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    return Status(StatusCode::kNotFound, dir.string() + ": not a database directory");
  }
  return ReadWithStableManifest(dir, [&] { return OpenOnce(dir, verify_checksums); });
}

Result<Database> Database::OpenOnce(const std::filesystem::path& dir, bool verify_checksums) {
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
    // with 48 made `query` search 24 silently (issue 14 item 4; validate checks every field).
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
      db.views_.push_back(
          {shard_index, static_cast<uint32_t>(i), owned->points(i), owned->coarse_field(i)});
      db.num_points_ += db.views_.back().points.size();
    }
    if (!owned->has_coarse_fields()) ++db.shards_without_coarse_fields_;
    // The point spans are copied out; labels are read again only for the top-k of a search.
    owned->ReleaseViewTablePages();
    db.size_bytes_ += header.file_size;
    db.shards_.push_back(std::move(owned));
  }
  if (db.views_.size() >= kInvalidViewId) {
    return Status(StatusCode::kOutOfRange, dir.string() + ": too many views");
  }
  db.manifest_ = std::move(manifest).value();
  return db;
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
