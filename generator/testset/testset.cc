#include "generator/testset/testset.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <optional>
#include <thread>

#include "base/atomic_file.h"
#include "base/json_number.h"
#include "base/json_schema.h"
#include "base/progress.h"
#include "base/thread_pool.h"
#include "generator/hand/hand_model.h"
#include "generator/render/blender.h"
#include "generator/sampling/natural_pose.h"
#include "generator/sampling/random.h"
#include "generator/sampling/shape_sampler.h"
#include "generator/testset/sequence.h"
#include "handdb_version.h"

namespace handdb {
namespace fs = std::filesystem;
namespace {

constexpr const char* kConfigSchema = "testset_config.schema.json";
constexpr const char* kPlanSchema = "testset_plan.schema.json";

std::string Numbered(const char* prefix, uint64_t i, int width) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%s%0*llu", prefix, width, static_cast<unsigned long long>(i));
  return buf;
}

std::array<double, 3> Vec3FromJson(const nlohmann::json& j) {
  return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()};
}

Status Invalid(const std::string& what, const std::string& message) {
  return Status(StatusCode::kInvalidArgument, what + ": " + message);
}

}  // namespace

uint32_t TestSetPlan::num_units() const {
  if (items.empty() || unit_size == 0) return 0;
  return static_cast<uint32_t>((items.size() + unit_size - 1) / unit_size);
}

std::vector<uint32_t> TestSetPlan::UnitItems(uint32_t unit) const {
  std::vector<uint32_t> ids;
  const uint64_t begin = static_cast<uint64_t>(unit) * unit_size;
  const uint64_t end = std::min<uint64_t>(items.size(), begin + unit_size);
  for (uint64_t i = begin; i < end; ++i) ids.push_back(static_cast<uint32_t>(i));
  return ids;
}

Result<nlohmann::json> MakeTestSetPlan(const nlohmann::json& config,
                                       const fs::path& config_path,
                                       bool clutter,
                                       bool forearm) {
  const std::string what = config_path.string();
  HANDDB_RETURN_IF_ERROR(ValidateJson(config, kConfigSchema, what));

  // Hand model: limits and hash from the loader, reference axes and scale from the JSON itself.
  auto hand_file =
      ResolveConfigPath(config.at("hand_model").get<std::string>(), config_path, "hand_model");
  if (!hand_file.ok()) return hand_file.status();
  const fs::path hand_path = *hand_file;
  auto hand = LoadHandModel(hand_path);
  if (!hand.ok()) return hand.status();
  auto hand_doc = ReadJsonFile(hand_path, "hand_model.schema.json");
  if (!hand_doc.ok()) return hand_doc.status();
  const JointLimits limits = hand->limits();

  // As the generation config's seed: 2^64 and above parse as a double that the schema's
  // "integer" accepts and a cast would turn into 0.
  Result<uint64_t> seed_checked = JsonInteger<uint64_t>(config.at("seed"), what, "seed");
  if (!seed_checked.ok()) return seed_checked.status();
  const uint64_t seed = *seed_checked;
  Result<uint32_t> count_checked = JsonInteger<uint32_t>(config.at("count"), what, "count");
  if (!count_checked.ok()) return count_checked.status();
  const uint32_t count = *count_checked;

  // Where the hand shapes come from: the shape library (basic shapes and PCA samples), or the
  // natural-pose sampler, which uses neither. Fields of the other source are errors.
  const nlohmann::json poses_cfg = config.value("poses", nlohmann::json::object());
  // A sequence's keyposes are natural poses: with "sequence" the method defaults to natural.
  const bool sequence = config.contains("sequence");
  const std::string method =
      poses_cfg.value("method", std::string(sequence ? "natural" : "library"));
  const bool natural = method == "natural";
  if (sequence && !natural) {
    return Invalid(what,
                   "sequence needs poses.method \"natural\" (its keyposes are natural poses)");
  }
  if (natural) {
    for (const char* key : {"shapes", "basic_fraction", "basic_names", "pca"}) {
      if (config.contains(key)) {
        return Invalid(what,
                       std::string(key) + " does not apply to poses.method \"natural\" (it " +
                           "samples poses without the shape library)");
      }
    }
  } else {
    for (const char* key : {"finger_spread", "abduction_spread"}) {
      if (poses_cfg.contains(key)) {
        return Invalid(what,
                       "poses." + std::string(key) +
                           " applies only to poses.method \"natural\", not \"library\"");
      }
    }
    if (!config.contains("shapes")) {
      return Invalid(what,
                     "shapes is required (the basic-shape library) unless poses.method is " +
                         std::string("\"natural\""));
    }
  }

  std::optional<fs::path> shapes_path;
  std::vector<NamedShape> library;
  std::vector<ShapeSample> basic;
  if (!natural) {
    auto shapes_file =
        ResolveConfigPath(config.at("shapes").get<std::string>(), config_path, "shapes");
    if (!shapes_file.ok()) return shapes_file.status();
    shapes_path = *shapes_file;
    auto loaded = LoadShapes(*shapes_path, limits);
    if (!loaded.ok()) return loaded.status();
    library = std::move(*loaded);
    std::vector<std::string> basic_names;
    if (config.contains("basic_names"))
      basic_names = config["basic_names"].get<std::vector<std::string>>();
    auto picked = SampleBasic(library, basic_names, 0);
    if (!picked.ok())
      return Status(picked.status().code(), what + ": " + picked.status().message());
    basic = std::move(*picked);
  }

  const double basic_fraction = natural ? 0.0 : config.value("basic_fraction", 0.25);
  const uint32_t num_basic = static_cast<uint32_t>(std::lround(basic_fraction * count));
  const uint32_t num_pca = natural ? 0 : count - num_basic;
  const uint32_t num_natural = natural ? count : 0;

  // Natural poses: a grip level shared by the fingers (generator/sampling/natural_pose.h), from a
  // stream of the test-set seed.
  NaturalPoseOptions natural_options;
  natural_options.finger_spread = poses_cfg.value("finger_spread", natural_options.finger_spread);
  natural_options.abduction_spread =
      poses_cfg.value("abduction_spread", natural_options.abduction_spread);
  natural_options.seed = seed;
  if (!natural_options.Check()) return Invalid(what, "bad poses options");
  std::vector<NaturalPose> natural_poses;
  uint64_t natural_clamped = 0;
  for (uint32_t i = 0; i < num_natural && !sequence; ++i) {
    natural_poses.push_back(SampleNaturalPose(natural_options, limits, i));
    natural_clamped += natural_poses.back().clamped ? 1 : 0;
  }

  // PCA shapes: Gaussian (or Sobol) coefficients in the basis of a shape set, with a stream seed
  // derived from the test-set seed so they never coincide with a database's Sobol points.
  const nlohmann::json pca_cfg = config.value("pca", nlohmann::json::object());
  std::vector<ShapeSample> pca_shapes;
  nlohmann::json pca_report = nlohmann::json::object();
  if (num_pca > 0) {
    std::vector<JointVector> basis_set;
    if (pca_cfg.contains("source")) {
      auto basis_path =
          ResolveConfigPath(pca_cfg["source"].get<std::string>(), config_path, "pca.source");
      if (!basis_path.ok()) return basis_path.status();
      auto basis_shapes = LoadShapes(*basis_path, limits);
      if (!basis_shapes.ok()) return basis_shapes.status();
      for (const auto& s : *basis_shapes) basis_set.push_back(s.joints);
      pca_report["basis"] = PathForPlan(*basis_path);
    } else {
      for (const auto& s : library) basis_set.push_back(s.joints);
      pca_report["basis"] = PathForPlan(*shapes_path);
    }
    auto basis = ComputePca(basis_set, pca_cfg.value("components", 6));
    if (!basis.ok()) return Invalid(what, basis.status().message());
    PcaSamplerOptions options;
    options.count = num_pca;
    options.sampling = pca_cfg.value("sampling", std::string("gaussian")) == "sobol"
                           ? CoefficientSampling::kSobol
                           : CoefficientSampling::kGaussian;
    options.scale = pca_cfg.value("scale", 1.0);
    options.max_sigma = pca_cfg.value("max_sigma", 3.0);
    options.seed = DeriveSeed(seed, kShapeStream, 0);
    if (!options.Check()) return Invalid(what, "bad pca options");
    uint64_t clamped = 0;
    pca_shapes = SamplePca(*basis, options, limits, &clamped);
    pca_report["components"] = basis->num_components();
    pca_report["explained"] = basis->explained;
    pca_report["sampling"] = options.sampling == CoefficientSampling::kSobol ? "sobol" : "gaussian";
    pca_report["scale"] = options.scale;
    pca_report["max_sigma"] = options.max_sigma;
    pca_report["clamped"] = clamped;
  }

  const nlohmann::json render_cfg = config.value("render", nlohmann::json::object());
  const int resolution = render_cfg.value("resolution", 256);
  double ortho_scale = render_cfg.value("ortho_scale", 0.0);
  if (ortho_scale <= 0) ortho_scale = hand->ortho_scale;
  if (ortho_scale <= 0)
    return Invalid(what, "render.ortho_scale is not set and the hand model gives none");
  std::optional<SequenceOptions> sequence_options;
  if (sequence) {
    auto parsed = SequenceOptions::FromJson(config.at("sequence"), what);
    if (!parsed.ok()) return parsed.status();
    sequence_options = *parsed;
    const uint64_t frames = static_cast<uint64_t>(parsed->sequences) * parsed->frames;
    if (frames != count) {
      return Invalid(what,
                     "count " + std::to_string(count) + " but the sequences have " +
                         std::to_string(frames) + " frames (sequence.sequences x sequence.frames)");
    }
  }
  // A sequence's frames default to one unit per sequence.
  const uint32_t unit_size =
      config.value("unit_size", sequence_options ? sequence_options->frames : 50u);

  const nlohmann::json photo_cfg = config.value("photo", nlohmann::json::object());
  nlohmann::json photo = {
      {"samples", photo_cfg.value("samples", PhotoSettings().samples)},
      {"skin_rgb", photo_cfg.value("skin_rgb", PhotoSettings().skin_rgb)},
      {"background_rgb", photo_cfg.value("background_rgb", PhotoSettings().background_rgb)},
      {"clutter", clutter || photo_cfg.value("clutter", false)},
  };
  // Written only when on, so plans of test sets made before the option stay byte-identical (a
  // rerun compares the plan on disk with the new one).
  const bool forearm_all = forearm || photo_cfg.value("forearm", false);
  if (forearm_all) photo["forearm"] = true;
  // A forearm on some photos: each item draws its own, so every item can be regenerated alone.
  // The CLI's --forearm puts it on all of them.
  if (photo_cfg.contains("forearm_fraction") && photo_cfg.value("forearm", false)) {
    return Invalid(what, "photo.forearm and photo.forearm_fraction exclude each other");
  }
  const bool forearm_some = !forearm_all && photo_cfg.contains("forearm_fraction");
  const double forearm_fraction = photo_cfg.value("forearm_fraction", 0.0);
  if (forearm_some) photo["forearm_fraction"] = forearm_fraction;

  // Items: the first num_basic are basic shapes, picked by a seeded shuffle of the library that
  // is repeated as often as needed (each shape about equally often); then the PCA samples. Every
  // item's direction (uniform on the sphere) and roll (uniform) come from its own seed.
  std::vector<uint32_t> basic_order;
  {
    Rng rng(DeriveSeed(seed, kTestViewStream, 0xBA51C));
    while (basic_order.size() < num_basic) {
      std::vector<uint32_t> perm(basic.size());
      for (uint32_t i = 0; i < perm.size(); ++i) perm[i] = i;
      for (size_t i = perm.size(); i > 1; --i) {
        const size_t j = static_cast<size_t>(rng.Next() % i);
        std::swap(perm[i - 1], perm[j]);
      }
      for (uint32_t p : perm) {
        if (basic_order.size() < num_basic) basic_order.push_back(p);
      }
    }
  }
  std::vector<SequenceFrame> sequence_frames;
  if (sequence_options) {
    sequence_frames = PlanSequenceFrames(*sequence_options,
                                         natural_options,
                                         limits,
                                         seed,
                                         resolution,
                                         Vec3FromJson(hand_doc->at("forward_axis")),
                                         Vec3FromJson(hand_doc->at("palm_normal")));
  }
  nlohmann::json items = nlohmann::json::array();
  for (uint32_t i = 0; i < count && sequence_options; ++i) {
    const SequenceFrame& f = sequence_frames[i];
    const std::array<double, 3>& d = f.direction;
    nlohmann::json item = {
        {"id", i},
        {"unit", i / unit_size},
        {"seed", f.seed},
        {"direction", d},
        {"theta", std::acos(std::clamp(d[2], -1.0, 1.0))},
        {"phi", std::atan2(d[1], d[0])},
        {"roll", f.roll},
        {"basic", false},
        {"shape_name", Numbered("s", f.sequence, 3) + Numbered("-f", f.frame, 6)},
        {"joints", nlohmann::json(f.joints)},
        {"coeffs", nlohmann::json::array()},
        {"clamped", f.clamped},
        {"clutter", f.clutter || photo.at("clutter").get<bool>()},
        {"photo_offset_px", f.photo_offset_px},
        {"sequence",
         {{"id", f.sequence}, {"frame", f.frame}, {"time", f.time}, {"leaving", f.leaving}}},
    };
    // Drawn per sequence: an arm does not come and go between frames.
    if (forearm_some) {
      item["forearm"] = Rng(DeriveSeed(f.seed, kForearmStream, 0)).Uniform() < forearm_fraction;
    }
    items.push_back(std::move(item));
  }
  for (uint32_t i = 0; i < count && !sequence_options; ++i) {
    const uint64_t item_seed = DeriveSeed(seed, kTestViewStream, i);
    Rng rng(item_seed);
    const double z = 2.0 * rng.Uniform() - 1.0;
    const double phi = 2.0 * M_PI * rng.Uniform();
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const std::array<double, 3> d = {r * std::cos(phi), r * std::sin(phi), z};
    const double roll = 2.0 * M_PI * rng.Uniform();
    nlohmann::json item = {
        {"id", i},
        {"unit", i / unit_size},
        {"seed", item_seed},
        {"direction", d},
        {"theta", std::acos(std::clamp(d[2], -1.0, 1.0))},
        {"phi", std::atan2(d[1], d[0])},
        {"roll", roll},
    };
    if (forearm_some) {
      item["forearm"] = Rng(DeriveSeed(item_seed, kForearmStream, 0)).Uniform() < forearm_fraction;
    }
    if (natural) {
      const NaturalPose& p = natural_poses[i];
      item["basic"] = false;
      item["shape_name"] = Numbered("natural-", i, 5);
      item["joints"] = nlohmann::json(p.joints);
      item["coeffs"] = {p.grip};
      item["clamped"] = p.clamped;
    } else if (i < num_basic) {
      const ShapeSample& s = basic[basic_order[i]];
      item["basic"] = true;
      item["shape_name"] = s.name;
      item["joints"] = nlohmann::json(s.joints);
      item["coeffs"] = nlohmann::json::array();
      item["clamped"] = false;
    } else {
      const ShapeSample& s = pca_shapes[i - num_basic];
      item["basic"] = false;
      item["shape_name"] = Numbered("pca-", i - num_basic, 5);
      item["joints"] = nlohmann::json(s.joints);
      item["coeffs"] = s.coeffs;
      item["clamped"] = s.clamped;
    }
    items.push_back(std::move(item));
  }

  nlohmann::json shapes_report;
  if (sequence_options) {
    shapes_report = {{"sequence_keyposes", "natural"},
                     {"natural_sampler",
                      {{"finger_spread", natural_options.finger_spread},
                       {"abduction_spread", natural_options.abduction_spread}}}};
  } else if (natural) {
    shapes_report = {{"natural", num_natural},
                     {"natural_sampler",
                      {{"finger_spread", natural_options.finger_spread},
                       {"abduction_spread", natural_options.abduction_spread},
                       {"clamped", natural_clamped}}}};
  } else {
    shapes_report = {{"library", PathForPlan(*shapes_path)},
                     {"basic", num_basic},
                     {"pca", num_pca},
                     {"pca_sampler", pca_report}};
  }
  nlohmann::json plan = {
      {"format", "handdb-testset-plan"},
      {"version", kTestSetFormatVersion},
      {"name", config.value("name", std::string("testset"))},
      {"seed", seed},
      {"config", config},
      {"hand_model", {{"path", PathForPlan(hand_path)}, {"sha256", hand->sha256}}},
      {"forward_axis", hand_doc->at("forward_axis")},
      {"palm_normal", hand_doc->at("palm_normal")},
      {"render", {{"resolution", resolution}, {"ortho_scale", ortho_scale}}},
      {"photo", photo},
      {"unit_size", unit_size},
      {"shapes", shapes_report},
      {"handdb_version", HANDDB_VERSION},
      {"items", items},
  };
  if (sequence_options) plan["sequence"] = sequence_options->ToJson();
  HANDDB_RETURN_IF_ERROR(ValidateJson(plan, kPlanSchema, what + " (test-set plan)"));
  return plan;
}

namespace {

// ParseTestSetPlan after the schema check; integers are narrowed by JsonIntegerOrThrow.
Result<TestSetPlan> ParseTestSetPlanFields(const nlohmann::json& doc, const std::string& what) {
  TestSetPlan plan;
  plan.doc = doc;
  plan.name = doc.at("name").get<std::string>();
  plan.seed = JsonIntegerOrThrow<uint64_t>(doc.at("seed"), "seed");
  plan.hand_model_path = doc.at("hand_model").at("path").get<std::string>();
  plan.hand_model_sha256 = doc.at("hand_model").at("sha256").get<std::string>();
  plan.forward_axis = Vec3FromJson(doc.at("forward_axis"));
  plan.palm_normal = Vec3FromJson(doc.at("palm_normal"));
  plan.resolution = JsonIntegerOrThrow<int>(doc.at("render").at("resolution"), "render.resolution");
  plan.ortho_scale = doc.at("render").at("ortho_scale").get<double>();
  plan.unit_size = JsonIntegerOrThrow<uint32_t>(doc.at("unit_size"), "unit_size");
  const auto& photo = doc.at("photo");
  plan.photo.samples = JsonIntegerOrThrow<int>(photo.at("samples"), "photo.samples");
  plan.photo.skin_rgb = Vec3FromJson(photo.at("skin_rgb"));
  plan.photo.background_rgb = Vec3FromJson(photo.at("background_rgb"));
  plan.photo.clutter = photo.at("clutter").get<bool>();
  plan.photo.forearm = photo.value("forearm", false);  // absent in plans written before it
  plan.photo.forearm_fraction = photo.value("forearm_fraction", plan.photo.forearm ? 1.0 : 0.0);
  for (const auto& j : doc.at("items")) {
    TestSetItem item;
    const std::string at = "items[" + std::to_string(plan.items.size()) + "].";
    item.id = JsonIntegerOrThrow<uint32_t>(j.at("id"), at + "id");
    item.unit = JsonIntegerOrThrow<uint32_t>(j.at("unit"), at + "unit");
    const std::string where = what + ": item " + std::to_string(plan.items.size());
    if (item.id != plan.items.size()) {
      return Status(
          StatusCode::kSchemaViolation,
          where + ": id " + std::to_string(item.id) + " (ids must be 0, 1, 2, ... in order)");
    }
    if (item.unit != item.id / plan.unit_size) {
      return Status(StatusCode::kSchemaViolation,
                    where + ": unit " + std::to_string(item.unit) + " but unit_size " +
                        std::to_string(plan.unit_size) + " puts it in unit " +
                        std::to_string(item.id / plan.unit_size));
    }
    item.basic = j.at("basic").get<bool>();
    item.shape_name = j.at("shape_name").get<std::string>();
    for (int k = 0; k < kNumJointAngles; ++k) item.joints[k] = j.at("joints").at(k).get<double>();
    item.coeffs = j.at("coeffs").get<std::vector<double>>();
    item.clamped = j.at("clamped").get<bool>();
    item.direction = Vec3FromJson(j.at("direction"));
    const double norm = std::hypot(item.direction[0], item.direction[1], item.direction[2]);
    if (std::abs(norm - 1.0) > 1e-6) {
      return Status(StatusCode::kOutOfRange,
                    where + ": direction has length " + std::to_string(norm) + ", expected 1");
    }
    item.theta = j.at("theta").get<double>();
    item.phi = j.at("phi").get<double>();
    item.roll = j.at("roll").get<double>();
    item.seed = JsonIntegerOrThrow<uint64_t>(j.at("seed"), at + "seed");
    item.forearm = j.value("forearm", plan.photo.forearm);
    item.clutter = j.value("clutter", plan.photo.clutter);
    if (j.contains("photo_offset_px")) {
      item.photo_offset_px = {j["photo_offset_px"].at(0).get<double>(),
                              j["photo_offset_px"].at(1).get<double>()};
    }
    if (j.contains("sequence")) {
      const nlohmann::json& sj = j["sequence"];
      TestSetSequenceRef ref;
      ref.sequence = JsonIntegerOrThrow<uint32_t>(sj.at("id"), at + "sequence.id");
      ref.frame = JsonIntegerOrThrow<uint32_t>(sj.at("frame"), at + "sequence.frame");
      ref.time = sj.at("time").get<double>();
      ref.leaving = sj.at("leaving").get<bool>();
      item.sequence = ref;
    }
    plan.items.push_back(std::move(item));
  }
  return plan;
}

}  // namespace

Result<TestSetPlan> ParseTestSetPlan(const nlohmann::json& doc, const std::string& what) {
  HANDDB_RETURN_IF_ERROR(ValidateJson(doc, kPlanSchema, what));
  try {
    return ParseTestSetPlanFields(doc, what);
  } catch (const JsonRangeError& e) {
    return Status(StatusCode::kOutOfRange, what + ": " + e.what());
  }
}

Result<TestSetPlan> ReadTestSetPlan(const fs::path& path) {
  auto doc = ReadJsonFile(path, kPlanSchema);
  if (!doc.ok()) return doc.status();
  return ParseTestSetPlan(*doc, path.string());
}

fs::path TestSetLabelPath(const fs::path& dir, uint32_t unit, uint32_t id) {
  return dir / "units" / UnitDirName(unit) / (RenderFileStem(id) + ".exr");
}
fs::path TestSetSidecarPath(const fs::path& dir, uint32_t unit, uint32_t id) {
  return dir / "units" / UnitDirName(unit) / (RenderFileStem(id) + ".json");
}
fs::path TestSetPhotoPath(const fs::path& dir, uint32_t unit, uint32_t id) {
  return dir / "photos" / UnitDirName(unit) / (RenderFileStem(id) + ".png");
}

bool TestSetRenderOptions::Check() const {
  CHECK_OPTION_GE(jobs, 1);
  return true;
}

namespace {

bool UnitComplete(const fs::path& dir, uint32_t unit, bool photos) {
  if (!fs::exists(dir / "units" / UnitDirName(unit) / "DONE")) return false;
  return !photos || fs::exists(dir / "photos" / UnitDirName(unit) / "DONE");
}

std::string LastNonEmptyLine(const fs::path& log) {
  std::ifstream in(log);
  std::string line;
  std::string last;
  while (std::getline(in, line)) {
    if (line.find_first_not_of(" \t\r") != std::string::npos) last = line;
  }
  return last;
}

}  // namespace

Result<TestSetRenderSummary> RenderTestSet(const fs::path& dir,
                                           const TestSetRenderOptions& options) {
  THROW_CHECK(options.Check());
  const auto start = std::chrono::steady_clock::now();
  auto plan = ReadTestSetPlan(dir / "testset_plan.json");
  if (!plan.ok()) return plan.status();
  auto blender = BlenderLauncher::Find(options.blender, options.scripts_dir, "render_testset.py");
  if (!blender.ok()) return blender.status();
  const fs::path hand_path = ResolvePlanPath(plan->hand_model_path);
  if (!fs::exists(hand_path)) {
    return Status(StatusCode::kNotFound,
                  hand_path.string() + ": hand model named by the plan not found");
  }
  std::error_code ec;
  fs::create_directories(dir / "logs", ec);
  if (ec) return Status(StatusCode::kIoError, (dir / "logs").string() + ": " + ec.message());

  TestSetRenderSummary summary;
  summary.units_total = plan->num_units();
  std::vector<uint32_t> todo;
  for (uint32_t u = 0; u < plan->num_units(); ++u) {
    if (UnitComplete(dir, u, options.photos)) {
      ++summary.units_skipped;
    } else {
      todo.push_back(u);
    }
  }
  Progress progress("testset render", todo.size(), options.progress, "units");
  std::mutex mu;
  std::atomic<bool> stop{false};  // set by the first failure: ends the other units' Blender runs
  const Status failure =
      ParallelForStatus(todo.size(), options.jobs, options.cancel, [&](size_t i) {
        const uint32_t unit = todo[i];
        const fs::path log = dir / "logs" / (UnitDirName(unit) + ".log");
        std::vector<std::string> args = {"--plan",
                                         (dir / "testset_plan.json").string(),
                                         "--unit",
                                         std::to_string(unit),
                                         "--out",
                                         dir.string()};
        if (!options.photos) args.push_back("--no-photos");
        // No retries: a failing unit stops the run at once (see RenderTestSet in testset.h).
        RunOptions run;
        run.log = log;
        run.stop_flags = {&stop, options.cancel};
        auto ran = blender->Run(args, run);
        if (!ran.ok()) std::ofstream(log, std::ios::app) << ran.status().message() << "\n";
        const int code = ran.ok() ? ran->exit_code : -1;
        if (code != 0 || !UnitComplete(dir, unit, options.photos)) {
          stop = true;
          // A cancelled run is reported as such below, not as this unit's failure.
          if (options.cancel != nullptr && options.cancel->load()) {
            return Status(StatusCode::kCancelled, "cancelled");
          }
          return Status(StatusCode::kExternalToolFailed,
                        "unit " + std::to_string(unit) + " failed (exit code " +
                            std::to_string(code) + "): " + LastNonEmptyLine(log) +
                            "; log: " + log.string());
        }
        {
          std::lock_guard<std::mutex> lock(mu);
          ++summary.units_rendered;
        }
        progress.Add();
        return Status::Ok();
      });
  progress.Finish();
  if (options.cancel != nullptr && options.cancel->load()) {
    return Status(StatusCode::kCancelled, "testset render cancelled; rerun to continue");
  }
  if (!failure.ok()) return failure;
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace handdb
