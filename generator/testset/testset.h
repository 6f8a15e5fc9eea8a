// Held-out test sets for the evaluation (docs/evaluation.md).
//
// `handdb testset CONFIG.json --out DIR` plans test views off the database grid — hand shapes
// sampled in the PCA shape space (Gaussian coefficients) plus a share of the named basic shapes,
// or "natural" poses that use no shape library (generator/sampling/natural_pose.h) — view
// directions uniform on the sphere, camera rolls uniform in [0, 2 pi) — from a seed that should
// differ from any database's; renders each one as a label EXR + sidecar (the database's render
// layout, so the converter's code gives its clean edges and normalised keypoints) and as a
// photo-like RGB image (blender_scripts/render_testset.py); then writes the ground truth. With a
// "sequence" object the items are the frames of short videos instead (generator/testset/
// sequence.h): their plan items say where they sit in their sequence, their background and the
// hand's shift in the photo.
//
// DIR/testset_plan.json            the plan (schemas/testset_plan.schema.json); a pure function of
//                                  the config and the files it names
// DIR/units/u00000/r000000.exr     label render of item 0 (+ r000000.json sidecar), DONE last
// DIR/photos/u00000/r000000.png    photo of item 0, DONE last
// DIR/sequences/s000/000000.png     sequence test sets: each sequence's photos in frame order
//                                  (relative symlinks), a folder to hand to a tracker
// DIR/testset.json                 ground truth (schemas/testset.schema.json), written last
//
// Everything is deterministic: item i's shape, direction, roll and clutter texture derive from
// (seed, i) only, so the same config gives the same plan bytes and the same images.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "generator/plan/plan.h"

namespace handdb {

constexpr int kTestSetFormatVersion = 1;
// Stream tag of the per-item randomness (direction, roll, basic-shape pick, clutter).
constexpr uint64_t kTestViewStream = 0x5445535456000000ull;  // "TESTV"
// Stream tag, under an item's seed, of whether its photo shows a forearm (photo.forearm_fraction).
constexpr uint64_t kForearmStream = 0x464f524541000000ull;  // "FOREA"

struct PhotoSettings {
  int samples = 16;                                        // Cycles samples per pixel
  std::array<double, 3> skin_rgb{0.80, 0.52, 0.40};        // sRGB 0..1 base colour of the skin
  std::array<double, 3> background_rgb{0.12, 0.14, 0.18};  // sRGB 0..1 of the plain background
  bool clutter = false;                                    // procedural textured background instead
  // A skin-coloured forearm (an elliptic cone from the wrist along -forward_axis, out of the
  // frame) in the photos only, as in real photos of hands; the label renders (the ground truth)
  // stay the hand alone. Measures the query's wrist cut (docs/evaluation.md).
  bool forearm = false;
  // The share of items whose photo shows the forearm, each drawn from its own seed (1 when
  // `forearm`); the plan marks every item. Absent from the config: all or none, by `forearm`.
  double forearm_fraction = 0;
};

// Where a frame of a sequence test set (generator/testset/sequence.h) sits in its sequence.
struct TestSetSequenceRef {
  uint32_t sequence = 0;
  uint32_t frame = 0;
  double time = 0;       // seconds
  bool leaving = false;  // inside a leave stretch: the photo is shifted by photo_offset_px
};

struct TestSetItem {
  uint32_t id = 0;  // == render id, shape id and dir id in its sidecar
  uint32_t unit = 0;
  bool basic = false;      // a named basic shape (the paper's "same shape" criterion applies)
  std::string shape_name;  // basic: library name; pca: "pca-00012"; natural: "natural-00012"
  JointVector joints{};
  std::vector<double> coeffs;         // pca coefficients; natural: [grip level]; basic: empty
  bool clamped = false;               // joint vector clamped to the limits
  std::array<double, 3> direction{};  // unit, hand -> camera, hand frame
  double theta = 0;
  double phi = 0;
  double roll = 0;       // camera roll, radians in [0, 2 pi)
  uint64_t seed = 0;     // DeriveSeed(seed, kTestViewStream, id): clutter texture etc.
  bool forearm = false;  // its photo shows a forearm
  bool clutter = false;  // its photo has the cluttered background (default: photo.clutter)
  // The hand's shift in the photo, px (x right, y down); the label render is not shifted.
  std::array<double, 2> photo_offset_px{};
  std::optional<TestSetSequenceRef> sequence;  // a frame of a sequence test set
};

struct TestSetPlan {
  std::string name;
  uint64_t seed = 0;
  std::string hand_model_path;  // as written (ResolvePlanPath)
  std::string hand_model_sha256;
  std::array<double, 3> forward_axis{};
  std::array<double, 3> palm_normal{};
  int resolution = 256;
  double ortho_scale = 0;
  uint32_t unit_size = 0;
  PhotoSettings photo;
  std::vector<TestSetItem> items;  // index == id
  nlohmann::json doc;

  uint32_t num_units() const;
  std::vector<uint32_t> UnitItems(uint32_t unit) const;  // item ids of a unit
};

// Builds the plan document from a parsed config (schemas/testset_config.schema.json).
// `clutter` and `forearm` force photo.clutter / photo.forearm on (the CLI's --clutter and
// --forearm). Errors name `config_path`.
Result<nlohmann::json> MakeTestSetPlan(const nlohmann::json& config,
                                       const std::filesystem::path& config_path,
                                       bool clutter,
                                       bool forearm = false);

// Schema check + consistency (ids dense, units consecutive, directions unit length, ...).
Result<TestSetPlan> ParseTestSetPlan(const nlohmann::json& doc, const std::string& what);
Result<TestSetPlan> ReadTestSetPlan(const std::filesystem::path& path);

// File names inside DIR.
std::filesystem::path TestSetLabelPath(const std::filesystem::path& dir,
                                       uint32_t unit,
                                       uint32_t id);
std::filesystem::path TestSetSidecarPath(const std::filesystem::path& dir,
                                         uint32_t unit,
                                         uint32_t id);
std::filesystem::path TestSetPhotoPath(const std::filesystem::path& dir,
                                       uint32_t unit,
                                       uint32_t id);
// DIR/sequences/s000/000012.png: frame 12 of sequence 0 (a link to its photo).
std::filesystem::path SequenceFramePath(const std::filesystem::path& dir,
                                        uint32_t sequence,
                                        uint32_t frame);

struct TestSetRenderOptions {
  int jobs = 1;                       // parallel Blender processes (each -t 1)
  std::filesystem::path blender;      // empty: $HANDDB_BLENDER, else `blender` on PATH
  std::filesystem::path scripts_dir;  // empty: $HANDDB_SCRIPTS_DIR, else RepoRoot()/blender_scripts
  bool photos = true;                 // also render the photo-like images
  bool progress = true;
  const std::atomic<bool>* cancel = nullptr;
  bool Check() const;
};

struct TestSetRenderSummary {
  uint32_t units_total = 0;
  uint32_t units_skipped = 0;  // already complete
  uint32_t units_rendered = 0;
  double seconds = 0;
};

// Runs blender_scripts/render_testset.py for every unit of DIR/testset_plan.json whose DONE
// markers are missing, `jobs` at a time; a unit's output goes to DIR/logs/uNNNNN.log. A failing
// unit stops the run with "unit 3 failed (exit code 1): <last line>; log: DIR/logs/u00003.log".
Result<TestSetRenderSummary> RenderTestSet(const std::filesystem::path& dir,
                                           const TestSetRenderOptions& options);

// Reads every item's label EXR and sidecar, converts it exactly as the database converter does
// (edges, normalisation) and writes DIR/testset.json: per item the pose (20 joint angles, view
// direction, camera roll), the 21 keypoints in the normalised frame, the normalisation and the
// files. Errors name the item's file.
Status WriteTestSetGroundTruth(const std::filesystem::path& dir, int num_threads, bool progress);

}  // namespace handdb
