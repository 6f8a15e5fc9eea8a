// The interface of the pose fit's solver plugin (libhanddb_fit.so: pose/fit.cc over Ceres, built
// by pose/CMakeLists.txt). Ceres' solver brings glog, gflags, SuiteSparse, METIS and more (12
// shared libraries and their relocations) into any process that links it, so handdb_pose does not:
// pose/fit_loader.cc opens the plugin (dlopen) on the first fit and calls FitPose,
// SilhouetteTermCost and DepthTermCost through this table. No Ceres type crosses it; handdb's own
// types do, so the plugin and its loader must be built from the same sources, which the ABI number
// and the layout below check before the table is used.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "base/status.h"
#include "generator/hand/kinematics.h"
#include "pose/fit.h"
#include "pose/fit_silhouette.h"

namespace handdb {

// Bumped when an entry's meaning or signature changes; the loader refuses another number.
inline constexpr int kFitPluginAbi = 2;

// The sizes of the types that cross the boundary, as each side was compiled.
using FitPluginLayout = std::array<size_t, 8>;
constexpr FitPluginLayout FitPluginLayoutOfThisBuild() {
  return {sizeof(PoseFit),
          sizeof(PoseFitOptions),
          sizeof(PoseFitEvidence),
          sizeof(PoseFitStart),
          sizeof(HandRig),
          sizeof(SilhouetteFields),
          sizeof(Status),
          sizeof(Result<PoseFit>)};
}

struct FitPluginApi {
  int abi = 0;
  FitPluginLayout layout{};
  Result<PoseFit> (*fit_pose)(const HandRig& rig,
                              const PoseFitStart& start,
                              const PoseFitEvidence& evidence,
                              const PoseFitOptions& options) = nullptr;
  double (*silhouette_term_cost)(const HandRig& rig,
                                 const SilhouetteFields& fields,
                                 bool mirrored,
                                 const PoseFitOptions& options,
                                 const JointVector& joints,
                                 const std::array<double, 4>& cam_from_hand,
                                 double scale,
                                 const std::array<double, 2>& shift,
                                 std::vector<double>* gradient) = nullptr;
  double (*depth_term_cost)(const HandRig& rig,
                            const PoseFitEvidence& evidence,
                            const PoseFitOptions& options,
                            const JointVector& joints,
                            const std::array<double, 4>& cam_from_hand,
                            std::vector<double>* gradient) = nullptr;
};

}  // namespace handdb

// The plugin's one exported symbol: its table, valid for the life of the process.
extern "C" const handdb::FitPluginApi* handdb_fit_plugin(void);
