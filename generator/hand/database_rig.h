// The rig a database was made with, read back from the database: the converter copies the hand
// model JSON into DB_DIR/hand_model.json (its sha256 is the one the manifest and every shard
// record as `hand_model.sha256`), so a database carries the bones, DOFs and camera references
// its views were rendered with, whatever happens to the configs/ it was made from.
#pragma once

#include <filesystem>
#include <string>

#include "base/status.h"
#include "generator/hand/camera.h"
#include "generator/hand/kinematics.h"

namespace handdb {

// DB_DIR/hand_model.json
constexpr char kDatabaseHandModelFileName[] = "hand_model.json";

struct DatabaseRig {
  HandRig rig;
  RenderSettings render;                  // the render resolution and ortho_scale of its views
  std::filesystem::path hand_model_file;  // the file the rig was read from
  bool from_database_copy = false;        // false: a database without the copy (fallback below)
};

// Reads DB_DIR/manifest.json's record of the hand model (metadata.hand_model.sha256) and render
// (metadata.generation), then DB_DIR/hand_model.json, refusing (kChecksumMismatch, one line naming
// the file and both hashes) a copy whose sha256 differs from the record. A database made without
// the copy falls back to the hand model its run named, if that file still exists with the
// recorded sha256: DB_DIR/render/plan.json's `hand_model.path` (what `handdb generate` leaves),
// else the generation config's `hand_model`; otherwise kNotFound says what was looked for.
Result<DatabaseRig> LoadDatabaseRig(const std::filesystem::path& db_dir);

}  // namespace handdb
