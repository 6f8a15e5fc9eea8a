// The one "rendered label view -> edge points in the normalised frame" path, shared by the
// converter (database views), label-image queries and the evaluation's clean queries: the render
// sidecar, the view conversion options and where a database records them, the edge rule followed
// by the normalisation. docs/conversion.md describes the rule and the messages.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "edges/edges.h"
#include "edges/normalise.h"
#include "format/view.h"

namespace handdb {

// The fields of a render sidecar the converter uses (docs/conventions.md "Sidecar JSON").
struct Sidecar {
  uint32_t render_id = 0;
  uint32_t unit = 0;
  uint32_t shape_id = 0;
  uint32_t dir_id = 0;
  std::array<double, kNumJointAngles> joint_angles{};
  std::array<double, 3> view_direction{};
  double view_theta = 0;
  double view_phi = 0;
  double camera_roll = 0;
  int resolution = 0;
  std::array<std::array<double, 3>, kNumKeypoints> keypoints_px{};
  std::string blender_version;
  std::string script_version;
  std::string hand_model_sha256;
};

// Errors (kBadJson, kSchemaViolation) name `what` and the field.
Result<Sidecar> ParseSidecar(const nlohmann::json& doc, const std::string& what);
Result<Sidecar> ReadSidecar(const std::filesystem::path& path);

struct ViewConversionOptions {
  EdgeOptions edges;
  JointPairs joint_pairs = DefaultJointPairs();
  bool Check() const { return edges.Check(); }
};

// Whether a hand reaching the outermost image row or column is an error: database views and
// evaluation views must show the whole hand; a query image may be cropped.
enum class BorderContact { kReject, kAllow };

struct LabelPoints {
  EdgeResult edges;  // rendered pixels
  Normalisation normalisation;
  std::vector<PointQ> points;  // normalised frame, sorted by (y, x), no duplicates
};

// A label image -> its edge pixels, the silhouette's normalisation and the normalised points.
// Errors start with `what`: kNoHand (no hand pixels, or ComputeNormalisation's), kOutOfRange
// (the hand touches the image border, with kReject).
Result<LabelPoints> LabelImageToPoints(const LabelImage& image,
                                       const ViewConversionOptions& options,
                                       BorderContact border,
                                       const std::string& what);

struct CanonicalView {
  ViewLabel label;
  std::vector<PointQ> points;  // normalised frame, sorted by (y, x), no duplicates
};

// One rendered view -> canonical view: LabelImageToPoints (kReject) plus the sidecar's pose in
// the normalised frame. `what` names the image in messages.
Result<CanonicalView> ConvertView(const LabelImage& image,
                                  const Sidecar& sidecar,
                                  const ViewConversionOptions& options,
                                  const std::string& what);

// The view conversion a database was made with, read back from its manifest metadata
// (`conversion.edges`: EdgeOptions::ToJson() plus joint_pairs, as the converter writes them).
// kNotFound when the metadata does not record the edge options; kBadJson when they are malformed.
// `what` (e.g. the manifest path) starts the messages.
Result<ViewConversionOptions> ViewConversionOptionsFromMetadata(const nlohmann::json& metadata,
                                                                const std::string& what);

// The view conversion to apply to a query against DB_DIR so it is converted like the database's
// views. The one fallback rule: the options DB_DIR/manifest.json records; the defaults when there
// is no readable manifest, or when it does not record them (then *fallback_reason, when given,
// says so; it is cleared otherwise); an error when they are recorded but malformed.
Result<ViewConversionOptions> ReadDatabaseViewConversion(const std::filesystem::path& db_dir,
                                                         std::string* fallback_reason = nullptr);
// The same rule on the `metadata` of a manifest already read (Database::manifest_metadata_json()),
// so the options come from the manifest whose shards are searched even when a convert has
// replaced DB_DIR/manifest.json since. `what` names the manifest in messages.
Result<ViewConversionOptions> DatabaseViewConversionFromMetadata(
    const nlohmann::json& metadata,
    const std::string& what,
    std::string* fallback_reason = nullptr);

}  // namespace handdb
