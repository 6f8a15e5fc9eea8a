// FitPose and SilhouetteTermCost for the processes that link handdb_pose: calls into the solver's
// plugin (pose/fit_plugin.h), opened on first use.
#include <dlfcn.h>

#include <cstdlib>
#include <mutex>
#include <stdexcept>
#include <string>

#include "pose/fit.h"
#include "pose/fit_plugin.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

constexpr const char* kFitPluginName = "libhanddb_fit.so";

struct LoadedFitPlugin {
  const FitPluginApi* api = nullptr;
  Status status;
};

Status OpenFitPlugin(const FitPluginApi** api) {
  std::string tried;
  for (const fs::path& candidate : PoseFitSolverCandidates()) {
    std::error_code ec;
    if (!fs::exists(candidate, ec)) {
      tried += (tried.empty() ? "" : ", ") + candidate.string();
      continue;
    }
    void* lib = ::dlopen(candidate.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (lib == nullptr) {
      return Status(StatusCode::kIoError,
                    "pose fit: " + candidate.string() + " cannot be loaded: " + ::dlerror());
    }
    using Entry = const FitPluginApi* (*)();
    const auto entry = reinterpret_cast<Entry>(::dlsym(lib, "handdb_fit_plugin"));
    const FitPluginApi* table = entry != nullptr ? entry() : nullptr;
    if (table == nullptr || table->abi != kFitPluginAbi ||
        table->layout != FitPluginLayoutOfThisBuild() || table->fit_pose == nullptr ||
        table->silhouette_term_cost == nullptr) {
      return Status(StatusCode::kUnsupportedVersion,
                    "pose fit: " + candidate.string() +
                        " is not the fit plugin of this handdb build (ABI " +
                        std::to_string(kFitPluginAbi) + "); reinstall handdb");
    }
    *api = table;
    return Status::Ok();
  }
  return Status(StatusCode::kNotFound,
                std::string("pose fit: the solver's plugin ") + kFitPluginName +
                    " is not installed (looked in " + tried +
                    "; set HANDDB_FIT_PLUGIN, or turn the fit off)");
}

const LoadedFitPlugin& FitPlugin() {
  static std::once_flag once;
  static LoadedFitPlugin plugin;
  std::call_once(once, [] { plugin.status = OpenFitPlugin(&plugin.api); });
  return plugin;
}

// The directory of the shared object (or executable) holding this function.
fs::path FitLoaderObjectDir() {
  Dl_info info{};
  if (::dladdr(reinterpret_cast<void*>(&FitLoaderObjectDir), &info) != 0 &&
      info.dli_fname != nullptr) {
    std::error_code ec;
    const fs::path p = fs::canonical(info.dli_fname, ec);
    if (!ec) return p.parent_path();
  }
  return {};
}

}  // namespace

std::vector<fs::path> PoseFitSolverCandidates() {
  if (const char* env = std::getenv("HANDDB_FIT_PLUGIN"); env != nullptr && *env != '\0') {
    return {fs::path(env)};
  }
  std::vector<fs::path> out;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    out.push_back(exe.parent_path() / kFitPluginName);
    out.push_back(exe.parent_path().parent_path() / "lib" / "handdb" / kFitPluginName);
  }
  if (const fs::path here = FitLoaderObjectDir(); !here.empty()) {
    out.push_back(here / kFitPluginName);
  }
  out.push_back(fs::path(HANDDB_FIT_PLUGIN_BUILD_DIR) / kFitPluginName);
  return out;
}

Status LoadPoseFitSolver() { return FitPlugin().status; }

Result<PoseFit> FitPose(const HandRig& rig,
                        const PoseFitStart& start,
                        const PoseFitEvidence& evidence,
                        const PoseFitOptions& options) {
  const LoadedFitPlugin& plugin = FitPlugin();
  if (!plugin.status.ok()) return plugin.status;
  return plugin.api->fit_pose(rig, start, evidence, options);
}

double SilhouetteTermCost(const HandRig& rig,
                          const SilhouetteFields& fields,
                          bool mirrored,
                          const PoseFitOptions& options,
                          const JointVector& joints,
                          const std::array<double, 4>& cam_from_hand,
                          double scale,
                          const std::array<double, 2>& shift,
                          std::vector<double>* gradient) {
  const LoadedFitPlugin& plugin = FitPlugin();
  if (!plugin.status.ok()) throw std::runtime_error(plugin.status.message());
  return plugin.api->silhouette_term_cost(
      rig, fields, mirrored, options, joints, cam_from_hand, scale, shift, gradient);
}

}  // namespace handdb
