// FitPose, SilhouetteTermCost and DepthTermCost for the processes that link handdb_pose: calls into
// the solver's plugin (pose/fit_plugin.h), opened on first use.
#include <dlfcn.h>

#include <mutex>
#include <stdexcept>
#include <string>

#include "base/plugin.h"
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
  auto lib = OpenPlugin(kFitPluginName, "HANDDB_FIT_PLUGIN", "the pose fit");
  if (!lib.ok()) {
    if (lib.status().code() != StatusCode::kNotFound) return lib.status();
    return Status(StatusCode::kNotFound, lib.status().message() + ", or turn the fit off");
  }
  using Entry = const FitPluginApi* (*)();
  const auto entry = reinterpret_cast<Entry>(::dlsym(*lib, "handdb_fit_plugin"));
  const FitPluginApi* table = entry != nullptr ? entry() : nullptr;
  if (table == nullptr || table->abi != kFitPluginAbi ||
      table->layout != FitPluginLayoutOfThisBuild() || table->fit_pose == nullptr ||
      table->silhouette_term_cost == nullptr) {
    return Status(StatusCode::kUnsupportedVersion,
                  "the pose fit: " + PluginFile(*lib, kFitPluginName) +
                      " is not the fit plugin of this handdb build (ABI " +
                      std::to_string(kFitPluginAbi) + "); reinstall handdb");
  }
  *api = table;
  return Status::Ok();
}

const LoadedFitPlugin& FitPlugin() {
  static std::once_flag once;
  static LoadedFitPlugin plugin;
  std::call_once(once, [] { plugin.status = OpenFitPlugin(&plugin.api); });
  return plugin;
}

}  // namespace

std::vector<fs::path> PoseFitSolverCandidates() {
  return PluginCandidates(kFitPluginName, "HANDDB_FIT_PLUGIN");
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

double DepthTermCost(const HandRig& rig,
                     const PoseFitEvidence& evidence,
                     const PoseFitOptions& options,
                     const JointVector& joints,
                     const std::array<double, 4>& cam_from_hand,
                     std::vector<double>* gradient) {
  const LoadedFitPlugin& plugin = FitPlugin();
  if (!plugin.status.ok()) throw std::runtime_error(plugin.status.message());
  return plugin.api->depth_term_cost(rig, evidence, options, joints, cam_from_hand, gradient);
}

}  // namespace handdb
