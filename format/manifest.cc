#include "format/manifest.h"

#include <sys/stat.h>

#include <algorithm>
#include <cstring>
#include <optional>
#include <regex>
#include <set>

#include "base/json_number.h"
#include "base/json_schema.h"

namespace handdb {

using nlohmann::json;

std::vector<ManifestLabelField> Manifest::ShardLabelFields() {
  return {
      {"render_id", "", 1, "render item in the plan (shape-major)"},
      {"shape_id", "", 1, "index into the plan's shape table"},
      {"dir_id", "", 1, "index into the plan's view-direction table"},
      {"joint_angles", "rad", kNumJointAngles, "hand-model DOF order (docs/conventions.md)"},
      {"view_direction", "", 3, "unit vector hand -> camera, hand frame"},
      {"view_theta", "rad", 1, "acos(view_direction.z)"},
      {"view_phi", "rad", 1, "atan2(view_direction.y, view_direction.x)"},
      {"camera_roll", "rad", 1, "of the rendered image; virtual roll adds 2 pi r / R"},
      {"keypoints", "px", kNumKeypoints * 3, "21 x (x, y, z), normalised frame"},
      {"source_diameter_px", "px", 1, "contour diameter in the rendered image"},
      {"scale", "px/px", 1, "normalised px per rendered px"},
      {"source_centre_px", "px", 2, "normalisation centre in the rendered image"},
      {"points", "px/16", 2, "edge points (int16 x, y), normalised frame"},
  };
}

void Manifest::AddShard(const ShardSummary& summary) {
  shards.push_back({summary.path.filename().string(),
                    summary.num_views,
                    summary.num_points,
                    summary.file_size,
                    summary.checksum});
  UpdateTotals();
}

void Manifest::UpdateTotals() {
  num_views = 0;
  for (const auto& s : shards) num_views += s.views;
  num_virtual_views = num_views * rolls;
}

json ManifestToJson(const Manifest& m) {
  json shards = json::array();
  for (const auto& s : m.shards) {
    shards.push_back({{"file", s.file},
                      {"views", s.views},
                      {"points", s.points},
                      {"bytes", s.bytes},
                      {"xxh3", s.xxh3}});
  }
  json labels = json::array();
  for (const auto& l : m.labels) {
    json field = {{"name", l.name}, {"unit", l.unit}, {"count", l.count}};
    if (!l.description.empty()) field["description"] = l.description;
    labels.push_back(std::move(field));
  }
  json skipped = json::array();
  for (const auto& s : m.skipped) {
    skipped.push_back({{"render_id", s.render_id}, {"file", s.file}, {"reason", s.reason}});
  }
  json out{{"format", kManifestFormat},
           {"version", m.version},
           {"tool_version", m.tool_version},
           {"rolls", m.rolls},
           {"num_views", m.num_views},
           {"num_virtual_views", m.num_virtual_views},
           {"shards", std::move(shards)},
           {"labels", std::move(labels)},
           {"metadata", m.metadata.is_null() ? json::object() : m.metadata},
           {"skipped", std::move(skipped)}};
  if (m.index) {
    out["index"] = {{"file", m.index->file},
                    {"kind", m.index->kind},
                    {"bytes", m.index->bytes},
                    {"xxh3", m.index->xxh3},
                    {"options", m.index->options}};
  }
  return out;
}

namespace {

// Meaning beyond the schema: totals add up, no shard listed twice.
Status CheckConsistency(const Manifest& m, const std::string& what, StatusCode code) {
  if (m.rolls > kMaxRolls) {
    return Status(StatusCode::kOutOfRange,
                  what + ": rolls is " + std::to_string(m.rolls) + ", more than the " +
                      std::to_string(kMaxRolls) + " a database may have");
  }
  uint64_t views = 0;
  std::set<std::string> files;
  for (const auto& s : m.shards) {
    views += s.views;
    if (!files.insert(s.file).second) {
      return Status(code, what + ": shard '" + s.file + "' is listed twice");
    }
  }
  if (views != m.num_views) {
    return Status(code,
                  what + ": num_views is " + std::to_string(m.num_views) + " but the shards hold " +
                      std::to_string(views) + " views");
  }
  if (m.num_virtual_views != m.num_views * m.rolls) {
    return Status(code,
                  what + ": num_virtual_views is " + std::to_string(m.num_virtual_views) +
                      ", expected num_views x rolls = " + std::to_string(m.num_views) + " x " +
                      std::to_string(m.rolls));
  }
  return Status::Ok();
}

}  // namespace

Result<Manifest> ManifestFromJson(const json& doc, const std::string& what) {
  HANDDB_RETURN_IF_ERROR(ValidateJson(doc, "manifest.schema.json", what));
  Manifest m;
  try {
    m.version = JsonIntegerOrThrow<int>(doc.at("version"), "version");
    m.tool_version = doc.at("tool_version").get<std::string>();
    m.rolls = JsonIntegerOrThrow<uint32_t>(doc.at("rolls"), "rolls");
    m.num_views = JsonIntegerOrThrow<uint64_t>(doc.at("num_views"), "num_views");
    m.num_virtual_views =
        JsonIntegerOrThrow<uint64_t>(doc.at("num_virtual_views"), "num_virtual_views");
    for (const auto& s : doc.at("shards")) {
      const std::string at = "shards[" + std::to_string(m.shards.size()) + "].";
      m.shards.push_back({s.at("file").get<std::string>(),
                          JsonIntegerOrThrow<uint64_t>(s.at("views"), at + "views"),
                          JsonIntegerOrThrow<uint64_t>(s.at("points"), at + "points"),
                          JsonIntegerOrThrow<uint64_t>(s.at("bytes"), at + "bytes"),
                          s.at("xxh3").get<std::string>()});
    }
    m.labels.clear();
    for (const auto& l : doc.at("labels")) {
      const std::string at = "labels[" + std::to_string(m.labels.size()) + "].count";
      m.labels.push_back({l.at("name").get<std::string>(),
                          l.at("unit").get<std::string>(),
                          JsonIntegerOrThrow<uint32_t>(l.at("count"), at),
                          l.value("description", "")});
    }
    m.metadata = doc.at("metadata");
    for (const auto& s : doc.at("skipped")) {
      const std::string at = "skipped[" + std::to_string(m.skipped.size()) + "].render_id";
      m.skipped.push_back({JsonIntegerOrThrow<render_id_t>(s.at("render_id"), at),
                           s.at("file").get<std::string>(),
                           s.at("reason").get<std::string>()});
    }
    if (doc.contains("index")) {
      const json& ix = doc.at("index");
      m.index = ManifestIndex{ix.at("file").get<std::string>(),
                              ix.at("kind").get<std::string>(),
                              JsonIntegerOrThrow<uint64_t>(ix.at("bytes"), "index.bytes"),
                              ix.at("xxh3").get<std::string>(),
                              ix.value("options", json::object())};
    }
  } catch (const JsonRangeError& e) {
    return Status(StatusCode::kOutOfRange, what + ": " + e.what());
  } catch (const json::exception& e) {
    // The schema has been checked, so this is a value out of the C++ type's range.
    return Status(StatusCode::kSchemaViolation, what + ": " + e.what());
  }
  HANDDB_RETURN_IF_ERROR(CheckConsistency(m, what, StatusCode::kSizeMismatch));
  return m;
}

namespace {

// Shard metadata key -> manifest field (JSON pointers into ManifestToJson), docs/format.md §8.
struct CrossCheckedField {
  const char* shard;
  const char* manifest;
};
constexpr CrossCheckedField kCrossCheckedFields[] = {
    {"/rolls", "/rolls"},
    {"/tool/version", "/tool_version"},
    {"/generation", "/metadata/generation"},
    {"/hand_model", "/metadata/hand_model"},
    {"/labels", "/metadata/labels"},
    {"/shapes", "/metadata/shapes"},
    {"/conversion/edges", "/metadata/conversion/edges"},
    {"/conversion/normalisation", "/metadata/conversion/normalisation"},
};

// "/metadata/shapes/3/name" -> "metadata.shapes[3].name".
std::string DottedPath(const std::string& pointer) {
  std::string out;
  size_t i = 0;
  while (i < pointer.size()) {
    const size_t next = pointer.find('/', i + 1);
    const std::string seg = pointer.substr(i + 1, next == std::string::npos ? next : next - i - 1);
    const bool index = !seg.empty() && seg.find_first_not_of("0123456789") == std::string::npos;
    out += index ? "[" + seg + "]" : (out.empty() ? "" : ".") + seg;
    i = next == std::string::npos ? pointer.size() : next;
  }
  return out;
}

// A value for a one-line message: compact JSON, at most 60 characters.
std::string Short(const json& doc, const std::string& pointer) {
  const json::json_pointer ptr(pointer);
  if (!doc.contains(ptr)) return "absent";
  std::string text = doc.at(ptr).dump();
  if (text.size() > 60) text = text.substr(0, 57) + "...";
  return text;
}

// The first place where `a` and `b` differ, as a JSON pointer relative to both ("" = the whole).
std::string FirstDifference(const json& a, const json& b) {
  const json patch = json::diff(a, b);
  if (patch.empty()) return "";
  std::string path = patch[0].at("path").get<std::string>();
  // An element appended to an array is at ".../-": name the array instead.
  if (path.size() >= 2 && path.compare(path.size() - 2, 2, "/-") == 0) path.resize(path.size() - 2);
  return path;
}

std::optional<ManifestSkipped> SkippedFromJson(const json& s) {
  if (!s.is_object() || !s.contains("render_id") || !s["render_id"].is_number_unsigned() ||
      !s.contains("file") || !s["file"].is_string() || !s.contains("reason") ||
      !s["reason"].is_string() || s["render_id"].get<uint64_t>() > kInvalidRenderId) {
    return std::nullopt;
  }
  return ManifestSkipped{s["render_id"].get<render_id_t>(),
                         s["file"].get<std::string>(),
                         s["reason"].get<std::string>()};
}

std::string SkippedText(const ManifestSkipped& s) {
  return "render " + std::to_string(s.render_id) + " (" + s.file + ": " + s.reason + ")";
}

}  // namespace

ManifestShardCheck::ManifestShardCheck(const Manifest& manifest)
    : manifest_json_(ManifestToJson(manifest)) {
  for (const ManifestSkipped& s : manifest.skipped) {
    skipped_listed_.insert({s.render_id, s.file, s.reason});
  }
}

std::vector<std::string> ManifestShardCheck::Check(const ManifestShard& entry,
                                                   const json& metadata) {
  std::vector<std::string> out;
  if (!metadata.is_object()) return out;
  for (const CrossCheckedField& field : kCrossCheckedFields) {
    const json::json_pointer shard_ptr(field.shard);
    if (!metadata.contains(shard_ptr)) continue;
    const json& value = metadata.at(shard_ptr);
    const json::json_pointer manifest_ptr(field.manifest);
    if (manifest_json_.contains(manifest_ptr) && !manifest_json_.at(manifest_ptr).is_null()) {
      const json& expected = manifest_json_.at(manifest_ptr);
      if (expected == value) continue;
      const std::string at = FirstDifference(expected, value);
      out.push_back(DottedPath(field.manifest + at) + " is " +
                    Short(manifest_json_, field.manifest + at) + " in the manifest but " +
                    Short(metadata, field.shard + at) + " in the shard's metadata (" +
                    DottedPath(field.shard + at) + ")");
      continue;
    }
    auto [it, first] = first_.try_emplace(field.shard, value, entry.file);
    if (first || it->second.first == value) continue;
    const std::string at = FirstDifference(it->second.first, value);
    out.push_back(DottedPath(field.shard + at) + " is " + Short(metadata, field.shard + at) +
                  " in the shard's metadata but " + Short(it->second.first, at) + " in " +
                  it->second.second + " (the manifest does not record " +
                  DottedPath(field.manifest) + ")");
  }
  // The unit a shard was converted from is the number in its file name (shard-00007.hdb: 7).
  static const std::regex kShardFile(R"(shard-([0-9]{1,9})(\.next)?\.hdb)");
  std::smatch m;
  if (metadata.contains("unit") && metadata["unit"].is_number_unsigned() &&
      std::regex_match(entry.file, m, kShardFile) &&
      std::stoull(m[1].str()) != metadata["unit"].get<uint64_t>()) {
    out.push_back("the manifest lists it as " + entry.file + " but its metadata records unit " +
                  metadata["unit"].dump());
  }
  if (metadata.contains("skipped") && metadata["skipped"].is_array()) {
    shards_record_skipped_ = true;
    for (const json& s : metadata["skipped"]) {
      const std::optional<ManifestSkipped> skipped = SkippedFromJson(s);
      if (!skipped) {
        out.push_back("metadata skipped[] holds a malformed entry " + s.dump().substr(0, 60));
        continue;
      }
      const SkippedKey key{skipped->render_id, skipped->file, skipped->reason};
      skipped_recorded_.insert(key);
      if (!skipped_listed_.count(key)) {
        out.push_back("its metadata records skipped " + SkippedText(*skipped) +
                      ", which the manifest's skipped[] does not list");
      }
    }
  }
  return out;
}

std::vector<std::string> ManifestShardCheck::Finish() const {
  std::vector<std::string> out;
  if (!shards_record_skipped_) return out;
  for (const SkippedKey& key : skipped_listed_) {
    if (skipped_recorded_.count(key)) continue;
    out.push_back("skipped[] lists " +
                  SkippedText({std::get<0>(key), std::get<1>(key), std::get<2>(key)}) +
                  ", which no shard's metadata records");
  }
  return out;
}

std::string ManifestLabelsMismatch(const Manifest& manifest) {
  const std::vector<ManifestLabelField> record = Manifest::ShardLabelFields();
  for (size_t i = 0; i < std::max(record.size(), manifest.labels.size()); ++i) {
    auto text = [](const std::vector<ManifestLabelField>& fields, size_t k) {
      if (k >= fields.size()) return std::string("absent");
      return "{" + fields[k].name + ", unit '" + fields[k].unit + "', count " +
             std::to_string(fields[k].count) + "}";
    };
    const bool same = i < record.size() && i < manifest.labels.size() &&
                      record[i].name == manifest.labels[i].name &&
                      record[i].unit == manifest.labels[i].unit &&
                      record[i].count == manifest.labels[i].count;
    if (!same) {
      return "labels[" + std::to_string(i) + "] is " + text(manifest.labels, i) +
             ", the v1.0 view record has " + text(record, i);
    }
  }
  return "";
}

std::string ShardFinalFileName(const std::string& file) {
  if (!IsShardStagingFileName(file)) return file;
  return file.substr(0, file.size() - std::strlen(kShardStagingSuffix)) + ".hdb";
}

bool IsShardStagingFileName(const std::string& file) {
  static const std::regex kStaging(R"(shard-[0-9]+\.next\.hdb)");
  return std::regex_match(file, kStaging);
}

ManifestStamp StampManifest(const std::filesystem::path& db_dir) {
  struct stat st {};
  if (::stat((db_dir / kManifestFileName).c_str(), &st) != 0) return {};
  ManifestStamp stamp;
  stamp.device = static_cast<uint64_t>(st.st_dev);
  stamp.inode = static_cast<uint64_t>(st.st_ino);
  stamp.size = static_cast<int64_t>(st.st_size);
  stamp.mtime_ns = int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec;
  stamp.ctime_ns = int64_t{st.st_ctim.tv_sec} * 1000000000 + st.st_ctim.tv_nsec;
  return stamp;
}

Result<Manifest> ReadManifest(const std::filesystem::path& db_dir) {
  const auto path = db_dir / kManifestFileName;
  Result<json> doc = ReadJsonFile(path, "manifest.schema.json");
  if (!doc.ok()) return doc.status();
  return ManifestFromJson(*doc, path.string());
}

Status WriteManifest(const std::filesystem::path& db_dir, const Manifest& manifest) {
  const auto path = db_dir / kManifestFileName;
  HANDDB_RETURN_IF_ERROR(CheckConsistency(manifest, path.string(), StatusCode::kInvalidArgument));
  const json doc = ManifestToJson(manifest);
  Status schema = ValidateJson(doc, "manifest.schema.json", path.string());
  if (!schema.ok()) return Status(StatusCode::kInvalidArgument, schema.message());
  return WriteJsonFileAtomic(path, doc);
}

}  // namespace handdb
