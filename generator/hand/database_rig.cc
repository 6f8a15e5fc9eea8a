#include "generator/hand/database_rig.h"

#include <vector>

#include "base/json_schema.h"
#include "base/sha256.h"
#include "format/manifest.h"
#include "generator/hand/hand_model.h"
#include "generator/plan/plan.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// The hand model files a database made before the copy may still name, most specific first.
std::vector<fs::path> FallbackHandModelFiles(const fs::path& db_dir, const json& metadata) {
  std::vector<fs::path> out;
  const fs::path plan_path = db_dir / "render" / "plan.json";
  std::error_code ec;
  if (fs::is_regular_file(plan_path, ec)) {
    auto plan = ReadJsonFile(plan_path, "");
    if (plan.ok() && plan->is_object() && plan->contains("hand_model") &&
        (*plan)["hand_model"].is_object() && (*plan)["hand_model"].contains("path") &&
        (*plan)["hand_model"]["path"].is_string()) {
      out.push_back(ResolvePlanPath((*plan)["hand_model"]["path"].get<std::string>()));
    }
  }
  const json* config = nullptr;
  if (metadata.contains("generation") && metadata["generation"].is_object() &&
      metadata["generation"].contains("config")) {
    config = &metadata["generation"]["config"];
  }
  if (config != nullptr && config->is_object() && config->contains("hand_model") &&
      (*config)["hand_model"].is_string()) {
    out.push_back(ResolvePlanPath((*config)["hand_model"].get<std::string>()));
  }
  return out;
}

}  // namespace

Result<DatabaseRig> LoadDatabaseRig(const fs::path& db_dir) {
  auto manifest = ReadManifest(db_dir);
  if (!manifest.ok()) return manifest.status();
  const std::string manifest_path = (db_dir / kManifestFileName).string();
  const json& metadata = manifest->metadata;
  if (!metadata.contains("hand_model") || !metadata["hand_model"].is_object() ||
      !metadata["hand_model"].contains("sha256") || !metadata["hand_model"]["sha256"].is_string()) {
    return Status(StatusCode::kSchemaViolation,
                  manifest_path + ": metadata does not record the hand model (hand_model.sha256)");
  }
  const std::string expected = metadata["hand_model"]["sha256"].get<std::string>();
  auto render = RenderSettings::FromMetadata(metadata, manifest_path);
  if (!render.ok()) return render.status();

  const fs::path copy = db_dir / kDatabaseHandModelFileName;
  std::error_code ec;
  const bool have_copy = fs::exists(fs::symlink_status(copy, ec));
  fs::path file;
  if (have_copy) {
    file = copy;
  } else {
    std::string looked;
    for (const fs::path& candidate : FallbackHandModelFiles(db_dir, metadata)) {
      auto sha = Sha256File(candidate);
      if (sha.ok() && *sha == expected) {
        file = candidate;
        break;
      }
      looked += (looked.empty() ? "" : ", ") + candidate.string() +
                (sha.ok() ? " (sha256 " + *sha + ")" : " (missing)");
    }
    if (file.empty()) {
      return Status(StatusCode::kNotFound,
                    copy.string() + ": no such file, and no hand model with the sha256 " +
                        expected + " the database records was found" +
                        (looked.empty() ? "" : " (looked at " + looked + ")"));
    }
  }
  auto model = LoadHandModel(file);
  if (!model.ok()) return model.status();
  if (model->sha256 != expected) {
    return Status(StatusCode::kChecksumMismatch,
                  file.string() + ": sha256 " + model->sha256 + " differs from the " + expected +
                      " the database records (" + manifest_path + ": hand_model.sha256)");
  }
  auto rig = HandRig::Create(*model);
  if (!rig.ok()) return rig.status();
  return DatabaseRig{std::move(rig).value(), *render, file, have_copy};
}

}  // namespace handdb
