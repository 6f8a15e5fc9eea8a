#include "edges/view_conversion.h"

#include <cmath>
#include <utility>

#include "base/json_schema.h"
#include "edges/normalise.h"
#include "format/manifest.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// Sidecar parsing: every field checked for presence and type, messages name the field.

Status FieldError(const std::string& what, const std::string& field, const std::string& problem) {
  return Status(StatusCode::kSchemaViolation, what + ": field '" + field + "': " + problem);
}

Result<double> GetNumber(const json& doc, const std::string& what, const char* field) {
  auto it = doc.find(field);
  if (it == doc.end()) return FieldError(what, field, "missing");
  if (!it->is_number()) return FieldError(what, field, "not a number");
  const double v = it->get<double>();
  if (!std::isfinite(v)) return FieldError(what, field, "not finite");
  return v;
}

Result<uint32_t> GetId(const json& doc, const std::string& what, const char* field) {
  auto it = doc.find(field);
  if (it == doc.end()) return FieldError(what, field, "missing");
  if (!it->is_number_unsigned() || it->get<uint64_t>() > UINT32_MAX) {
    return FieldError(what, field, "not a non-negative 32-bit integer (value: " + it->dump() + ")");
  }
  return it->get<uint32_t>();
}

Result<std::string> GetString(const json& doc,
                              const std::string& what,
                              const char* field,
                              bool required) {
  auto it = doc.find(field);
  if (it == doc.end()) {
    if (required) return FieldError(what, field, "missing");
    return std::string();
  }
  if (!it->is_string()) return FieldError(what, field, "not a string");
  return it->get<std::string>();
}

// Fills `out` from a JSON array of `n` finite numbers.
Status GetNumbers(
    const json& doc, const std::string& what, const std::string& field, size_t n, double* out) {
  if (!doc.is_array() || doc.size() != n) {
    return FieldError(what, field, "expected an array of " + std::to_string(n) + " numbers");
  }
  for (size_t i = 0; i < n; ++i) {
    if (!doc[i].is_number() || !std::isfinite(doc[i].get<double>())) {
      return FieldError(what, field + "[" + std::to_string(i) + "]", "not a finite number");
    }
    out[i] = doc[i].get<double>();
  }
  return Status::Ok();
}

}  // namespace

Result<Sidecar> ParseSidecar(const json& doc, const std::string& what) {
  if (!doc.is_object()) return Status(StatusCode::kSchemaViolation, what + ": not a JSON object");
  Sidecar s;
#define HANDDB_ASSIGN(dst, expr)                    \
  do {                                              \
    auto handdb_r_ = (expr);                        \
    if (!handdb_r_.ok()) return handdb_r_.status(); \
    dst = std::move(handdb_r_.value());             \
  } while (0)
  HANDDB_ASSIGN(s.render_id, GetId(doc, what, "render_id"));
  HANDDB_ASSIGN(s.unit, GetId(doc, what, "unit"));
  HANDDB_ASSIGN(s.shape_id, GetId(doc, what, "shape_id"));
  HANDDB_ASSIGN(s.dir_id, GetId(doc, what, "dir_id"));
  HANDDB_ASSIGN(s.view_theta, GetNumber(doc, what, "view_theta"));
  HANDDB_ASSIGN(s.view_phi, GetNumber(doc, what, "view_phi"));
  HANDDB_ASSIGN(s.camera_roll, GetNumber(doc, what, "camera_roll"));
  uint32_t resolution = 0;
  HANDDB_ASSIGN(resolution, GetId(doc, what, "resolution"));
  if (resolution == 0 || resolution > 65536) {
    return FieldError(
        what, "resolution", "out of range (value: " + std::to_string(resolution) + ")");
  }
  s.resolution = static_cast<int>(resolution);
  HANDDB_ASSIGN(s.blender_version, GetString(doc, what, "blender_version", true));
  HANDDB_ASSIGN(s.script_version, GetString(doc, what, "script_version", false));
  HANDDB_ASSIGN(s.hand_model_sha256, GetString(doc, what, "hand_model_sha256", false));
#undef HANDDB_ASSIGN
  for (const char* f : {"joint_angles", "view_direction", "keypoints_px"}) {
    if (!doc.contains(f)) return FieldError(what, f, "missing");
  }
  HANDDB_RETURN_IF_ERROR(GetNumbers(
      doc["joint_angles"], what, "joint_angles", kNumJointAngles, s.joint_angles.data()));
  HANDDB_RETURN_IF_ERROR(
      GetNumbers(doc["view_direction"], what, "view_direction", 3, s.view_direction.data()));
  const json& kp = doc["keypoints_px"];
  if (!kp.is_array() || kp.size() != kNumKeypoints) {
    return FieldError(what,
                      "keypoints_px",
                      "expected an array of " + std::to_string(kNumKeypoints) + " [u, v, depth]");
  }
  for (int k = 0; k < kNumKeypoints; ++k) {
    HANDDB_RETURN_IF_ERROR(GetNumbers(
        kp[k], what, "keypoints_px[" + std::to_string(k) + "]", 3, s.keypoints_px[k].data()));
  }
  return s;
}

Result<Sidecar> ReadSidecar(const fs::path& path) {
  auto doc = ReadJsonFile(path, "render_sidecar.schema.json");
  if (!doc.ok()) return doc.status();
  return ParseSidecar(*doc, path.string());
}

Result<LabelPoints> LabelImageToPoints(const LabelImage& image,
                                       const ViewConversionOptions& options,
                                       BorderContact border,
                                       const std::string& what) {
  THROW_CHECK(options.Check());
  LabelPoints out;
  out.edges = ExtractEdges(image, options.joint_pairs, options.edges);
  if (out.edges.num_hand_pixels == 0) {
    return Status(StatusCode::kNoHand, what + ": no hand pixels (empty view)");
  }
  if (border == BorderContact::kReject && out.edges.touches_border) {
    return Status(StatusCode::kOutOfRange,
                  what + ": the hand touches the image border (cropped silhouette)");
  }
  auto norm = ComputeNormalisation(out.edges.silhouette);
  if (!norm.ok()) return Status(norm.status().code(), what + ": " + norm.status().message());
  out.normalisation = *norm;
  out.points = NormalisePixels(out.edges.edges, out.normalisation);
  return out;
}

Result<CanonicalView> ConvertView(const LabelImage& image,
                                  const Sidecar& sidecar,
                                  const ViewConversionOptions& options,
                                  const std::string& what) {
  auto converted = LabelImageToPoints(image, options, BorderContact::kReject, what);
  if (!converted.ok()) return converted.status();
  const Normalisation* norm = &converted->normalisation;

  CanonicalView view;
  view.points = std::move(converted->points);
  ViewLabel& label = view.label;
  label.render_id = sidecar.render_id;
  label.shape_id = sidecar.shape_id;
  label.dir_id = sidecar.dir_id;
  for (int i = 0; i < kNumJointAngles; ++i) {
    label.joint_angles[i] = static_cast<float>(sidecar.joint_angles[i]);
  }
  for (int i = 0; i < 3; ++i)
    label.view_direction[i] = static_cast<float>(sidecar.view_direction[i]);
  label.view_theta = static_cast<float>(sidecar.view_theta);
  label.view_phi = static_cast<float>(sidecar.view_phi);
  label.camera_roll = static_cast<float>(sidecar.camera_roll);
  for (int k = 0; k < kNumKeypoints; ++k) {
    label.keypoints[k] = NormaliseKeypoint(sidecar.keypoints_px[k], *norm);
  }
  label.source_diameter_px = static_cast<float>(norm->diameter);
  label.scale = static_cast<float>(norm->scale);
  label.source_centre_px = {static_cast<float>(norm->centre_x), static_cast<float>(norm->centre_y)};
  return view;
}

Result<ViewConversionOptions> ViewConversionOptionsFromMetadata(const json& metadata,
                                                                const std::string& what) {
  const json* edges = nullptr;
  if (metadata.is_object() && metadata.contains("conversion") &&
      metadata["conversion"].is_object() && metadata["conversion"].contains("edges")) {
    edges = &metadata["conversion"]["edges"];
  }
  if (edges == nullptr || edges->is_null()) {
    return Status(StatusCode::kNotFound,
                  what + ": metadata does not record the edge options (conversion.edges)");
  }
  auto bad = [&](const std::string& problem) {
    return Status(StatusCode::kBadJson, what + ": conversion.edges: " + problem);
  };
  auto edge_options = EdgeOptions::FromJson(*edges, what + ": conversion.edges");
  if (!edge_options.ok()) return edge_options.status();
  ViewConversionOptions options;
  options.edges = *edge_options;
  if (const auto pairs = edges->find("joint_pairs"); pairs != edges->end()) {
    if (!pairs->is_array()) return bad("joint_pairs not an array");
    JointPairs table;
    for (const json& pair : *pairs) {
      if (!pair.is_array() || pair.size() != 2 || !pair[0].is_number_integer() ||
          !pair[1].is_number_integer()) {
        return bad("joint_pairs entry " + pair.dump() + " is not a pair of link ids");
      }
      const int a = pair[0].get<int>();
      const int b = pair[1].get<int>();
      if (a < 1 || a > kNumLinks || b < 1 || b > kNumLinks || a == b) {
        return bad("joint_pairs entry " + pair.dump() + " is not a pair of link ids 1.." +
                   std::to_string(kNumLinks));
      }
      table.Add(a, b);
    }
    options.joint_pairs = table;
  }
  return options;
}

Result<ViewConversionOptions> ReadDatabaseViewConversion(const fs::path& db_dir,
                                                         std::string* fallback_reason) {
  if (fallback_reason != nullptr) fallback_reason->clear();
  auto manifest = ReadManifest(db_dir);
  if (!manifest.ok()) return ViewConversionOptions{};
  return DatabaseViewConversionFromMetadata(
      manifest->metadata, (db_dir / kManifestFileName).string(), fallback_reason);
}

Result<ViewConversionOptions> DatabaseViewConversionFromMetadata(const nlohmann::json& metadata,
                                                                 const std::string& what,
                                                                 std::string* fallback_reason) {
  if (fallback_reason != nullptr) fallback_reason->clear();
  auto recorded = ViewConversionOptionsFromMetadata(metadata, what);
  if (recorded.status().code() == StatusCode::kNotFound) {
    if (fallback_reason != nullptr) *fallback_reason = recorded.status().message();
    return ViewConversionOptions{};
  }
  return recorded;
}

}  // namespace handdb
