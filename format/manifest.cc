#include "format/manifest.h"

#include <set>

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
  return json{{"format", kManifestFormat},
              {"version", m.version},
              {"tool_version", m.tool_version},
              {"rolls", m.rolls},
              {"num_views", m.num_views},
              {"num_virtual_views", m.num_virtual_views},
              {"shards", std::move(shards)},
              {"labels", std::move(labels)},
              {"metadata", m.metadata.is_null() ? json::object() : m.metadata},
              {"skipped", std::move(skipped)}};
}

namespace {

// Meaning beyond the schema: totals add up, no shard listed twice.
Status CheckConsistency(const Manifest& m, const std::string& what, StatusCode code) {
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
    m.version = doc.at("version").get<int>();
    m.tool_version = doc.at("tool_version").get<std::string>();
    m.rolls = doc.at("rolls").get<uint32_t>();
    m.num_views = doc.at("num_views").get<uint64_t>();
    m.num_virtual_views = doc.at("num_virtual_views").get<uint64_t>();
    for (const auto& s : doc.at("shards")) {
      m.shards.push_back({s.at("file").get<std::string>(),
                          s.at("views").get<uint64_t>(),
                          s.at("points").get<uint64_t>(),
                          s.at("bytes").get<uint64_t>(),
                          s.at("xxh3").get<std::string>()});
    }
    m.labels.clear();
    for (const auto& l : doc.at("labels")) {
      m.labels.push_back({l.at("name").get<std::string>(),
                          l.at("unit").get<std::string>(),
                          l.at("count").get<uint32_t>(),
                          l.value("description", "")});
    }
    m.metadata = doc.at("metadata");
    for (const auto& s : doc.at("skipped")) {
      m.skipped.push_back({s.at("render_id").get<render_id_t>(),
                           s.at("file").get<std::string>(),
                           s.at("reason").get<std::string>()});
    }
  } catch (const json::exception& e) {
    // The schema has been checked, so this is a value out of the C++ type's range.
    return Status(StatusCode::kSchemaViolation, what + ": " + e.what());
  }
  HANDDB_RETURN_IF_ERROR(CheckConsistency(m, what, StatusCode::kSizeMismatch));
  return m;
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
