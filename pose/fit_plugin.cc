// The entry of libhanddb_fit.so: the table of pose/fit_plugin.h over this object's own FitPose,
// SilhouetteTermCost and DepthTermCost (pose/fit.cc). Everything else in the object is hidden, so
// its copies of handdb's libraries never stand in for the loading process's.
#include "pose/fit_plugin.h"

extern "C" __attribute__((visibility("default"))) const handdb::FitPluginApi* handdb_fit_plugin(
    void) {
  static const handdb::FitPluginApi kApi = {handdb::kFitPluginAbi,
                                            handdb::FitPluginLayoutOfThisBuild(),
                                            &handdb::FitPose,
                                            &handdb::SilhouetteTermCost,
                                            &handdb::DepthTermCost};
  return &kApi;
}
