// `handdb plan`: a generation config (schemas/config.schema.json) becomes a render plan
// (schemas/render_plan.schema.json, layout in docs/conventions.md "Plan JSON"): the sampled hand
// shapes, the sampled view directions, and the renders (shape-major: render_id = shape_index *
// num_directions + dir_index) cut into units of at most `unit_size` consecutive renders. A unit is
// the unit of work everywhere (one Blender process, one convert task, one shard). The plan is a
// pure function of the config and the files it names: same config -> identical bytes.
//
// Paths: a relative path in a config is looked up next to the config first, then under the
// repository root (RepoRoot()). Paths written into a plan are repository-relative when the file
// lies inside the repository (so plans are byte-identical across checkouts), absolute otherwise;
// readers resolve them with ResolvePlanPath().
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/repo_root.h"
#include "base/status.h"
#include "format/view.h"

namespace handdb {

constexpr int kPlanFormatVersion = 1;
// Renders (shapes x directions) a plan may hold (without a bound, pairs with k = 1000 would grow
// `plan` past 4 GB and a pca count of 10^9 would be std::bad_alloc). A plan takes ~0.9 KB of JSON
// per render, so 250,000 renders (~225 MB) still fit under the 256 MiB ReadJsonFile allows a plan;
// checked from the config's counts before any shape is sampled. pca-large has 22,016.
constexpr uint64_t kMaxPlanRenders = 250'000;
// A path as written in a plan / hand-model / shapes file -> a path to open.
std::filesystem::path ResolvePlanPath(const std::string& path_in_plan);
// A path as written in a config (generation or test-set) -> an existing file: absolute as is,
// relative next to `config_path` first, then under RepoRoot(). kNotFound names the config, the
// field and both places looked in.
Result<std::filesystem::path> ResolveConfigPath(const std::string& value,
                                                const std::filesystem::path& config_path,
                                                const std::string& field);
// A resolved file -> the path written into a plan: repository-relative when inside the
// repository, else absolute.
std::string PathForPlan(const std::filesystem::path& resolved);

struct PlanShape {
  uint32_t id = 0;
  std::string name;
  JointVector joints{};
  std::vector<double> coeffs;  // sampler coordinates (PCA coefficients, pair parameter, ...)
};

struct PlanDirection {
  uint32_t id = 0;
  std::array<double, 3> direction{};  // unit vector towards the camera, hand frame
  double theta = 0;                   // acos(d.z)
  double phi = 0;                     // atan2(d.y, d.x)
};

struct PlanRender {
  uint32_t render_id = 0;
  uint32_t shape_id = 0;
  uint32_t dir_id = 0;
  double roll = 0;    // always 0: rolls are virtual (applied to point sets later)
  uint64_t seed = 0;  // DeriveSeed(plan seed, unit, index in unit), for anything random per render
};

struct PlanUnit {
  uint32_t id = 0;
  std::vector<PlanRender> renders;
};

struct Plan {
  uint64_t seed = 0;
  std::string hand_model_path;    // as written in the plan (see ResolvePlanPath)
  std::string hand_model_sha256;  // of the hand-model JSON file
  int resolution = 256;
  double ortho_scale = 0;
  int rolls = 48;
  uint32_t unit_size = 0;
  std::vector<PlanShape> shapes;          // index == id
  std::vector<PlanDirection> directions;  // index == id
  std::vector<PlanUnit> units;            // index == id
  nlohmann::json doc;                     // the whole plan document (config, sampling reports, ...)

  uint64_t num_renders() const { return static_cast<uint64_t>(shapes.size()) * directions.size(); }
  uint64_t num_views() const { return num_renders() * static_cast<uint64_t>(rolls); }
};

struct PlanSummary {
  uint64_t shapes = 0;
  uint64_t directions = 0;
  uint64_t rolls = 0;
  uint64_t renders = 0;
  uint64_t views = 0;  // renders x rolls (virtual views)
  uint64_t units = 0;
  uint64_t clamped_shapes = 0;     // samples that had to be clamped to the joint limits
  double covering_radius_deg = 0;  // of the direction set
  std::string shapes_method;
  std::string views_method;
};

// Builds the plan document from a parsed config. `config_path` resolves relative paths and names
// the config in messages. Errors: kSchemaViolation, kInvalidArgument (e.g. an icosahedron count
// that is not 10*4^k+2), kNotFound/kBadJson for the files it names.
Result<nlohmann::json> MakePlan(const nlohmann::json& config,
                                const std::filesystem::path& config_path,
                                PlanSummary* summary = nullptr);

// Reads CONFIG, builds the plan, checks it against its schema and writes it atomically.
Status WritePlanFromConfig(const std::filesystem::path& config_path,
                           const std::filesystem::path& plan_path,
                           PlanSummary* summary = nullptr);

// Parses a plan document: schema check, then consistency (ids dense and in order, render ids
// shape-major, units consecutive and at most unit_size, joints and directions of each render
// equal to those of its shape and direction). Messages name `what`.
Result<Plan> ParsePlan(const nlohmann::json& doc, const std::string& what);
Result<Plan> ReadPlan(const std::filesystem::path& plan_path);

// File names inside a run directory (docs/conventions.md "Files and directories").
std::string UnitDirName(uint32_t unit_id);       // "u00007"
std::string RenderFileStem(uint32_t render_id);  // "r000123"

}  // namespace handdb
