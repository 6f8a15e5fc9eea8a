#include "generator/plan/plan.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "base/json_number.h"
#include "base/json_schema.h"
#include "generator/hand/hand_model.h"
#include "generator/sampling/random.h"
#include "generator/sampling/shape_sampler.h"
#include "generator/sampling/view_sampler.h"
#include "handdb_version.h"

namespace handdb {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr const char* kDefaultHandModel = "configs/hands/webxr_generic_right.json";
constexpr const char* kDefaultLibrary = "configs/shapes/basic.json";

double Round(double x) {
  // Directions come from sin/cos and PCA samples from sums of products: rounding to 1e-15 hides
  // last-ulp differences between libm versions and FMA contraction, so plans stay byte-identical.
  return std::round(x * 1e15) / 1e15;
}

json NumbersJson(const double* begin, const double* end) {
  json out = json::array();
  for (const double* p = begin; p != end; ++p) out.push_back(Round(*p));
  return out;
}

json JointsJson(const JointVector& j) { return NumbersJson(j.data(), j.data() + j.size()); }

struct SampledShapes {
  std::vector<ShapeSample> samples;
  json report;
  uint64_t clamped = 0;
};

// `num_dirs` directions: the shapes a method would give are counted and refused above
// kMaxPlanRenders / num_dirs before any is sampled.
Result<SampledShapes> SampleShapes(const json& spec,
                                   const fs::path& config_path,
                                   const HandModel& model,
                                   uint64_t seed,
                                   uint64_t num_dirs) {
  const std::string cfg = config_path.string();
  const std::string method = spec.at("method").get<std::string>();
  auto bad = [&](const std::string& msg) {
    return Status(StatusCode::kInvalidArgument, cfg + ": shapes: " + msg);
  };
  auto check_count = [&](uint64_t shapes, const std::string& how) -> Status {
    if (shapes <= kMaxPlanRenders / num_dirs) return Status::Ok();
    return bad(how + " give " + std::to_string(shapes) + " shapes x " + std::to_string(num_dirs) +
               " directions, more than the " + std::to_string(kMaxPlanRenders) +
               " renders a plan may hold");
  };
  // A huge scale or span overflows the coefficients (the plan would record null); refused here,
  // naming the field, rather than by `render` naming the plan.
  auto check_finite = [&](const std::vector<ShapeSample>& samples, const char* field) -> Status {
    for (size_t i = 0; i < samples.size(); ++i) {
      bool finite = true;
      for (double c : samples[i].coeffs) finite = finite && std::isfinite(c);
      for (double j : samples[i].joints) finite = finite && std::isfinite(j);
      if (!finite) {
        return bad(std::string(field) + " " + spec[field].dump() +
                   " gives a coefficient or joint angle that is not finite (sample " +
                   std::to_string(i) + ")");
      }
    }
    return Status::Ok();
  };
  auto allow_only = [&](std::initializer_list<const char*> keys) -> Status {
    for (const auto& [key, value] : spec.items()) {
      bool ok = key == "method";
      for (const char* k : keys) ok = ok || key == k;
      if (!ok) return bad("'" + key + "' does not apply to method '" + method + "'");
    }
    return Status::Ok();
  };
  const JointLimits limits = model.limits();
  Result<fs::path> library_path = ResolveConfigPath(
      spec.value("library", std::string(kDefaultLibrary)), config_path, "shapes.library");
  if (!library_path.ok()) return library_path.status();
  Result<std::vector<NamedShape>> library = LoadShapes(*library_path, limits);
  if (!library.ok()) return library.status();

  SampledShapes out;
  out.report = {{"method", method}, {"library", PathForPlan(*library_path)}};
  std::vector<std::string> names = spec.value("names", std::vector<std::string>{});
  uint32_t count = 0;
  if (spec.contains("count")) {
    Result<uint32_t> checked = JsonInteger<uint32_t>(spec["count"], cfg, "shapes.count");
    if (!checked.ok()) return checked.status();
    count = *checked;
  }

  if (method == "basic" || method == "pairs") {
    if (method == "basic") {
      HANDDB_RETURN_IF_ERROR(allow_only({"library", "names", "count"}));
    } else {
      HANDDB_RETURN_IF_ERROR(allow_only({"library", "names", "count", "k", "include_endpoints"}));
    }
    if (!names.empty() && count != 0) return bad("give either 'names' or 'count', not both");
    Result<std::vector<ShapeSample>> basic = SampleBasic(*library, names, count);
    if (!basic.ok()) return bad(basic.status().message());
    if (method == "basic") {
      HANDDB_RETURN_IF_ERROR(check_count(basic->size(), "basic shapes would"));
      out.samples = std::move(*basic);
    } else {
      if (basic->size() < 2) return bad("pairs needs at least 2 basic shapes");
      const int k = spec.value("k", 1);
      const bool endpoints = spec.value("include_endpoints", false);
      const uint64_t n = basic->size();
      HANDDB_RETURN_IF_ERROR(check_count(
          n * (n - 1) / 2 * static_cast<uint64_t>(k) + (endpoints ? n : 0),
          "pairs of " + std::to_string(n) + " basic shapes with k = " + std::to_string(k)));
      out.samples = SamplePairs(*basic, k, endpoints);
      out.report["k"] = k;
      out.report["include_endpoints"] = endpoints;
      out.report["basic_shapes"] = basic->size();
    }
    out.report["count"] = out.samples.size();
    out.report["clamped"] = 0;
    return out;
  }

  // pca / grid: a PCA basis of the source set.
  if (method == "pca") {
    HANDDB_RETURN_IF_ERROR(
        allow_only({"library", "source", "components", "count", "sampling", "scale", "max_sigma"}));
    if (count == 0) return bad("pca needs 'count' (number of samples)");
    HANDDB_RETURN_IF_ERROR(check_count(count, "pca count " + std::to_string(count) + " would"));
  } else {
    HANDDB_RETURN_IF_ERROR(allow_only({"library", "source", "components", "levels", "span"}));
    if (!spec.contains("levels")) return bad("grid needs 'levels'");
  }
  std::vector<NamedShape> source_shapes;
  std::string source_name = PathForPlan(*library_path);
  if (spec.contains("source")) {
    Result<fs::path> source_path =
        ResolveConfigPath(spec["source"].get<std::string>(), config_path, "shapes.source");
    if (!source_path.ok()) return source_path.status();
    Result<std::vector<NamedShape>> source = LoadShapes(*source_path, limits);
    if (!source.ok()) return source.status();
    source_shapes = std::move(*source);
    source_name = PathForPlan(*source_path);
  } else {
    source_shapes = *library;
  }
  std::vector<JointVector> set;
  for (const auto& s : source_shapes) set.push_back(s.joints);
  const int k = spec.value("components", std::min(8, static_cast<int>(set.size()) - 1));
  Result<PcaBasis> basis = ComputePca(set, k);
  if (!basis.ok()) return bad(basis.status().message());
  out.report["source"] = source_name;
  out.report["components"] = k;
  out.report["explained_variance"] = basis->explained;
  out.report["stddev"] = std::vector<double>(basis->stddev.data(), basis->stddev.data() + k);
  if (method == "pca") {
    PcaSamplerOptions opts;
    opts.count = count;
    const std::string sampling = spec.value("sampling", std::string("sobol"));
    opts.sampling =
        sampling == "gaussian" ? CoefficientSampling::kGaussian : CoefficientSampling::kSobol;
    opts.scale = spec.value("scale", 1.0);
    opts.max_sigma = spec.value("max_sigma", 3.0);
    opts.seed = seed;
    out.samples = SamplePca(*basis, opts, limits, &out.clamped);
    if (spec.contains("scale")) HANDDB_RETURN_IF_ERROR(check_finite(out.samples, "scale"));
    if (spec.contains("max_sigma")) HANDDB_RETURN_IF_ERROR(check_finite(out.samples, "max_sigma"));
    out.report["sampling"] = sampling;
    out.report["scale"] = opts.scale;
    out.report["max_sigma"] = opts.max_sigma;
  } else {
    std::vector<int> levels;
    if (spec["levels"].is_array()) {
      levels = spec["levels"].get<std::vector<int>>();
    } else {
      levels.assign(static_cast<size_t>(k), spec["levels"].get<int>());
    }
    uint64_t total = 1;
    for (int l : levels) {
      total *= static_cast<uint64_t>(std::max(l, 1));
      if (total > kMaxPlanRenders) break;  // no overflow: every level is <= 1000
    }
    HANDDB_RETURN_IF_ERROR(check_count(total, "grid levels would"));
    const double span = spec.value("span", 2.0);
    Result<std::vector<ShapeSample>> grid = SampleGrid(*basis, levels, span, limits, &out.clamped);
    if (!grid.ok()) return bad(grid.status().message());
    out.samples = std::move(*grid);
    if (spec.contains("span")) HANDDB_RETURN_IF_ERROR(check_finite(out.samples, "span"));
    out.report["levels"] = levels;
    out.report["span"] = span;
  }
  out.report["count"] = out.samples.size();
  out.report["clamped"] = out.clamped;
  return out;
}

// A views spec, checked and counted without generating a direction.
struct ViewsSpec {
  std::string method;
  int fibonacci_count = 0;  // method "fibonacci"
  int subdivisions = -1;    // method "icosahedron"
  uint64_t count = 0;       // directions it gives
};

Result<ViewsSpec> ParseViews(const json& spec, const fs::path& config_path) {
  const std::string cfg = config_path.string();
  ViewsSpec views;
  views.method = spec.at("method").get<std::string>();
  if (views.method == "fibonacci") {
    if (spec.contains("subdivisions")) {
      return Status(StatusCode::kInvalidArgument,
                    cfg + ": views: 'subdivisions' is for method 'icosahedron'");
    }
    views.fibonacci_count = spec.value("count", 86);
    views.count = static_cast<uint64_t>(std::max(views.fibonacci_count, 0));
    return views;
  }
  int k = spec.value("subdivisions", -1);
  if (spec.contains("count")) {
    const int from_count = IcosahedronSubdivisionsForCount(spec["count"].get<int>());
    if (from_count < 0) {
      return Status(StatusCode::kInvalidArgument,
                    cfg + ": views: icosahedron count " + spec["count"].dump() +
                        " is not 10*4^k+2 (12, 42, 162, 642, 2562, ...)");
    }
    if (k >= 0 && k != from_count) {
      return Status(StatusCode::kInvalidArgument, cfg + ": views: count and subdivisions disagree");
    }
    k = from_count;
  }
  if (k < 0) k = 1;
  views.subdivisions = k;
  // The schema bounds k to 0..8, so 4^k cannot overflow.
  views.count = 10 * (uint64_t{1} << (2 * k)) + 2;
  return views;
}

std::vector<Eigen::Vector3d> SampleViews(const ViewsSpec& views, json* report) {
  std::vector<Eigen::Vector3d> dirs;
  if (views.method == "fibonacci") {
    dirs = FibonacciDirections(views.fibonacci_count);
  } else {
    dirs = IcosahedronDirections(views.subdivisions);
    (*report)["subdivisions"] = views.subdivisions;
  }
  const int probes = static_cast<int>(std::clamp<size_t>(40 * dirs.size(), 20000, 200000));
  const CoveringRadius cover = ComputeCoveringRadius(dirs, probes);
  (*report)["method"] = views.method;
  (*report)["count"] = dirs.size();
  (*report)["covering_radius_deg"] = std::round(cover.radians * 180.0 / M_PI * 1e6) / 1e6;
  return dirs;
}

}  // namespace

fs::path ResolvePlanPath(const std::string& path_in_plan) {
  const fs::path p(path_in_plan);
  if (p.is_absolute()) return p;
  return RepoRoot() / p;
}

Result<fs::path> ResolveConfigPath(const std::string& value,
                                   const fs::path& config_path,
                                   const std::string& field) {
  const fs::path p(value);
  std::error_code ec;
  if (p.is_absolute()) {
    if (fs::exists(p, ec)) return p;
    return Status(StatusCode::kNotFound,
                  config_path.string() + ": " + field + ": " + value + ": no such file");
  }
  const fs::path next_to_config = config_path.parent_path() / p;
  if (fs::exists(next_to_config, ec)) return next_to_config;
  const fs::path in_repo = RepoRoot() / p;
  if (fs::exists(in_repo, ec)) return in_repo;
  return Status(StatusCode::kNotFound,
                config_path.string() + ": " + field + ": " + value + ": no such file (looked in " +
                    next_to_config.parent_path().string() + " and " + RepoRoot().string() + ")");
}

std::string PathForPlan(const fs::path& resolved) {
  std::error_code ec;
  const fs::path abs = fs::weakly_canonical(fs::absolute(resolved), ec);
  const fs::path root = fs::weakly_canonical(fs::absolute(RepoRoot()), ec);
  const fs::path rel = abs.lexically_relative(root);
  if (!rel.empty() && *rel.begin() != "..") return rel.generic_string();
  return abs.generic_string();
}

std::string UnitDirName(uint32_t unit_id) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "u%05u", unit_id);
  return buf;
}

std::string RenderFileStem(uint32_t render_id) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "r%06u", render_id);
  return buf;
}

Result<json> MakePlan(const json& config, const fs::path& config_path, PlanSummary* summary) {
  HANDDB_RETURN_IF_ERROR(ValidateJson(config, "config.schema.json", config_path.string()));
  const std::string cfg = config_path.string();
  // 2^64 and above parse as a float that the schema's "integer" accepts; the plan would then
  // record a float seed.
  const json& seed_json = config.at("seed");
  if (!seed_json.is_number_integer() ||
      (!seed_json.is_number_unsigned() && seed_json.get<int64_t>() < 0)) {
    return Status(StatusCode::kInvalidArgument,
                  cfg + ": seed " + config.at("seed").dump() +
                      " is not an integer in 0..18446744073709551615");
  }
  const uint64_t seed = config.at("seed").get<uint64_t>();

  Result<fs::path> hand_path = ResolveConfigPath(
      config.value("hand_model", std::string(kDefaultHandModel)), config_path, "hand_model");
  if (!hand_path.ok()) return hand_path.status();
  Result<HandModel> model = LoadHandModel(*hand_path);
  if (!model.ok()) return model.status();

  // Directions are counted first, from the config alone: their count bounds the shapes
  // (kMaxPlanRenders), and every count is checked before anything is sampled.
  Result<ViewsSpec> views = ParseViews(config.at("views"), config_path);
  if (!views.ok()) return views.status();
  if (views->count > kMaxPlanRenders) {
    return Status(
        StatusCode::kInvalidArgument,
        cfg + ": views: " + views->method +
            (views->subdivisions >= 0 ? " subdivisions " + std::to_string(views->subdivisions)
                                      : std::string()) +
            " give " + std::to_string(views->count) + " directions, more than the " +
            std::to_string(kMaxPlanRenders) + " renders a plan may hold");
  }
  Result<SampledShapes> shapes = SampleShapes(
      config.at("shapes"), config_path, *model, seed, std::max<uint64_t>(views->count, 1));
  if (!shapes.ok()) return shapes.status();
  json views_report = json::object();
  const std::vector<Eigen::Vector3d> dirs = SampleViews(*views, &views_report);

  const json render_cfg = config.value("render", json::object());
  const int resolution = render_cfg.value("resolution", 256);
  double ortho_scale = render_cfg.value("ortho_scale", model->ortho_scale);
  if (!(ortho_scale > 0)) {
    return Status(StatusCode::kInvalidArgument,
                  cfg + ": render.ortho_scale missing and the hand model gives none");
  }
  const int rolls = config.value("rolls", 48);
  const uint32_t unit_size = config.value("unit_size", 256u);

  const uint64_t num_shapes = shapes->samples.size();
  const uint64_t num_dirs = dirs.size();
  const uint64_t num_renders = num_shapes * num_dirs;
  if (num_renders > kMaxPlanRenders) {  // checked per method above; this guards a new method
    return Status(StatusCode::kInvalidArgument,
                  cfg + ": " + std::to_string(num_renders) + " renders, more than the " +
                      std::to_string(kMaxPlanRenders) + " a plan may hold");
  }

  json plan = json::object();
  plan["format"] = "handdb-plan";
  plan["version"] = kPlanFormatVersion;
  plan["tool"] = {{"name", "handdb"}, {"version", HANDDB_VERSION}};
  plan["seed"] = seed;
  plan["config"] = config;
  plan["hand_model"] = {
      {"path", PathForPlan(*hand_path)}, {"sha256", model->sha256}, {"name", model->name}};
  if (!model->asset_sha256.empty()) plan["hand_model"]["asset_sha256"] = model->asset_sha256;
  plan["render"] = {{"resolution", resolution}, {"ortho_scale", ortho_scale}, {"engine", "cycles"}};
  plan["rolls"] = rolls;
  plan["unit_size"] = unit_size;
  plan["sampling"] = {{"shapes", shapes->report}, {"views", views_report}};

  json shape_list = json::array();
  for (uint64_t i = 0; i < num_shapes; ++i) {
    const ShapeSample& s = shapes->samples[i];
    json js = {{"id", i},
               {"name", s.name},
               {"joints", JointsJson(s.joints)},
               {"coeffs", NumbersJson(s.coeffs.data(), s.coeffs.data() + s.coeffs.size())}};
    if (s.clamped) js["clamped"] = true;
    shape_list.push_back(std::move(js));
  }
  std::vector<std::array<double, 3>> dir_values;
  json dir_list = json::array();
  for (uint64_t i = 0; i < num_dirs; ++i) {
    const Eigen::Vector3d& d = dirs[i];
    const std::array<double, 3> v = {Round(d.x()), Round(d.y()), Round(d.z())};
    dir_values.push_back(v);
    dir_list.push_back({{"id", i},
                        {"direction", v},
                        {"theta", Round(std::acos(std::clamp(d.z(), -1.0, 1.0)))},
                        {"phi", Round(std::atan2(d.y(), d.x()))}});
  }
  json units = json::array();
  for (uint64_t first = 0; first < num_renders; first += unit_size) {
    const uint64_t unit_id = units.size();
    const uint64_t last = std::min(num_renders, first + unit_size);
    json renders = json::array();
    for (uint64_t r = first; r < last; ++r) {
      const uint64_t shape = r / num_dirs;
      const uint64_t dir = r % num_dirs;
      renders.push_back({{"render_id", r},
                         {"shape_id", shape},
                         {"dir_id", dir},
                         {"joints", shape_list[shape]["joints"]},
                         {"direction", dir_values[dir]},
                         {"roll", 0.0},
                         {"seed", DeriveSeed(seed, unit_id, r - first)}});
    }
    units.push_back({{"id", unit_id}, {"renders", std::move(renders)}});
  }
  plan["totals"] = {{"shapes", num_shapes},
                    {"directions", num_dirs},
                    {"renders", num_renders},
                    {"views", num_renders * static_cast<uint64_t>(rolls)},
                    {"units", units.size()}};
  plan["shapes"] = std::move(shape_list);
  plan["directions"] = std::move(dir_list);
  plan["units"] = std::move(units);

  if (summary != nullptr) {
    summary->shapes = num_shapes;
    summary->directions = num_dirs;
    summary->rolls = static_cast<uint64_t>(rolls);
    summary->renders = num_renders;
    summary->views = num_renders * static_cast<uint64_t>(rolls);
    summary->units = plan["units"].size();
    summary->clamped_shapes = shapes->clamped;
    summary->covering_radius_deg = views_report["covering_radius_deg"].get<double>();
    summary->shapes_method = shapes->report["method"].get<std::string>();
    summary->views_method = views_report["method"].get<std::string>();
  }
  return plan;
}

Status WritePlanFromConfig(const fs::path& config_path,
                           const fs::path& plan_path,
                           PlanSummary* summary) {
  Result<json> config = ReadJsonFile(config_path, "config.schema.json");
  if (!config.ok()) return config.status();
  Result<json> plan = MakePlan(*config, config_path, summary);
  if (!plan.ok()) return plan.status();
  // The plan we write must be one we would accept.
  Result<Plan> parsed = ParsePlan(*plan, plan_path.string());
  THROW_CHECK_MSG(parsed.ok(),
                  "handdb plan produced an invalid plan: " << parsed.status().message());
  return WriteJsonFileAtomic(plan_path, *plan);
}

namespace {

// ParsePlan after the schema check; integers are narrowed by JsonIntegerOrThrow.
Result<Plan> ParsePlanFields(const json& doc, const std::string& what) {
  auto bad = [&](const std::string& msg) {
    return Status(StatusCode::kSchemaViolation, what + ": " + msg);
  };
  Plan plan;
  plan.seed = JsonIntegerOrThrow<uint64_t>(doc["seed"], "/seed");
  plan.hand_model_path = doc["hand_model"]["path"].get<std::string>();
  plan.hand_model_sha256 = doc["hand_model"]["sha256"].get<std::string>();
  plan.resolution = JsonIntegerOrThrow<int>(doc["render"]["resolution"], "/render/resolution");
  plan.ortho_scale = doc["render"]["ortho_scale"].get<double>();
  plan.rolls = JsonIntegerOrThrow<int>(doc["rolls"], "/rolls");
  plan.unit_size = JsonIntegerOrThrow<uint32_t>(doc["unit_size"], "/unit_size");

  const json& shapes = doc["shapes"];
  for (size_t i = 0; i < shapes.size(); ++i) {
    PlanShape s;
    s.id = JsonIntegerOrThrow<uint32_t>(shapes[i]["id"], "/shapes/" + std::to_string(i) + "/id");
    if (s.id != i)
      return bad("/shapes/" + std::to_string(i) + "/id: " + std::to_string(s.id) + ", expected " +
                 std::to_string(i));
    s.name = shapes[i]["name"].get<std::string>();
    for (int j = 0; j < kNumJointAngles; ++j) s.joints[j] = shapes[i]["joints"][j].get<double>();
    s.coeffs = shapes[i]["coeffs"].get<std::vector<double>>();
    plan.shapes.push_back(std::move(s));
  }
  const json& dirs = doc["directions"];
  for (size_t i = 0; i < dirs.size(); ++i) {
    PlanDirection d;
    d.id = JsonIntegerOrThrow<uint32_t>(dirs[i]["id"], "/directions/" + std::to_string(i) + "/id");
    if (d.id != i)
      return bad("/directions/" + std::to_string(i) + "/id: " + std::to_string(d.id) +
                 ", expected " + std::to_string(i));
    for (int k = 0; k < 3; ++k) d.direction[k] = dirs[i]["direction"][k].get<double>();
    const double norm =
        std::sqrt(d.direction[0] * d.direction[0] + d.direction[1] * d.direction[1] +
                  d.direction[2] * d.direction[2]);
    if (std::abs(norm - 1.0) > 1e-6) {
      return bad("/directions/" + std::to_string(i) + "/direction: norm " + std::to_string(norm) +
                 " is not 1");
    }
    d.theta = dirs[i]["theta"].get<double>();
    d.phi = dirs[i]["phi"].get<double>();
    plan.directions.push_back(d);
  }
  const uint64_t num_dirs = plan.directions.size();
  const uint64_t num_renders = plan.num_renders();
  uint64_t next_render = 0;
  const json& units = doc["units"];
  for (size_t u = 0; u < units.size(); ++u) {
    const std::string where = "/units/" + std::to_string(u);
    PlanUnit unit;
    unit.id = JsonIntegerOrThrow<uint32_t>(units[u]["id"], where + "/id");
    if (unit.id != u)
      return bad(where + "/id: " + std::to_string(unit.id) + ", expected " + std::to_string(u));
    const json& renders = units[u]["renders"];
    if (renders.size() > plan.unit_size) {
      return bad(where + ": " + std::to_string(renders.size()) + " renders, unit_size is " +
                 std::to_string(plan.unit_size));
    }
    for (size_t i = 0; i < renders.size(); ++i) {
      const json& jr = renders[i];
      const std::string rw = where + "/renders/" + std::to_string(i);
      PlanRender r;
      r.render_id = JsonIntegerOrThrow<uint32_t>(jr["render_id"], rw + "/render_id");
      r.shape_id = JsonIntegerOrThrow<uint32_t>(jr["shape_id"], rw + "/shape_id");
      r.dir_id = JsonIntegerOrThrow<uint32_t>(jr["dir_id"], rw + "/dir_id");
      r.roll = jr["roll"].get<double>();
      r.seed = jr.contains("seed") ? JsonIntegerOrThrow<uint64_t>(jr["seed"], rw + "/seed") : 0;
      if (r.render_id != next_render) {
        return bad(rw + "/render_id: " + std::to_string(r.render_id) + ", expected " +
                   std::to_string(next_render));
      }
      if (r.shape_id != next_render / num_dirs || r.dir_id != next_render % num_dirs) {
        return bad(rw + ": shape_id " + std::to_string(r.shape_id) + ", dir_id " +
                   std::to_string(r.dir_id) + " do not match render_id " +
                   std::to_string(r.render_id) + " (shape-major)");
      }
      for (int j = 0; j < kNumJointAngles; ++j) {
        if (jr["joints"][j].get<double>() != plan.shapes[r.shape_id].joints[j]) {
          return bad(rw + "/joints/" + std::to_string(j) + ": differs from shape " +
                     std::to_string(r.shape_id));
        }
      }
      for (int k = 0; k < 3; ++k) {
        if (jr["direction"][k].get<double>() != plan.directions[r.dir_id].direction[k]) {
          return bad(rw + "/direction: differs from direction " + std::to_string(r.dir_id));
        }
      }
      if (r.roll != 0.0) return bad(rw + "/roll: rolls are virtual, renders must have roll 0");
      unit.renders.push_back(r);
      ++next_render;
    }
    if (u + 1 < units.size() && unit.renders.size() != plan.unit_size) {
      return bad(where + ": only the last unit may hold fewer than unit_size renders");
    }
    plan.units.push_back(std::move(unit));
  }
  if (next_render != num_renders) {
    return bad("units cover " + std::to_string(next_render) + " renders, shapes x directions is " +
               std::to_string(num_renders));
  }
  plan.doc = doc;
  return plan;
}

}  // namespace

Result<Plan> ParsePlan(const json& doc, const std::string& what) {
  HANDDB_RETURN_IF_ERROR(ValidateJson(doc, "render_plan.schema.json", what));
  try {
    return ParsePlanFields(doc, what);
  } catch (const JsonRangeError& e) {
    return Status(StatusCode::kOutOfRange, what + ": " + e.what());
  }
}

Result<Plan> ReadPlan(const fs::path& plan_path) {
  Result<json> doc = ReadJsonFile(plan_path, "");
  if (!doc.ok()) return doc.status();
  return ParsePlan(*doc, plan_path.string());
}

}  // namespace handdb
