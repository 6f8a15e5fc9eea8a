// Test helper (tests only, header-only): the rig of the shipped hand model, which the rig, camera,
// fit and export tests pose.
#pragma once

#include <utility>

#include "base/repo_root.h"
#include "base/status.h"
#include "generator/hand/hand_model.h"
#include "generator/hand/kinematics.h"

namespace handdb::testing {

inline HandRig ShippedRig() {
  auto model = LoadHandModel(RepoRoot() / "configs/hands/webxr_generic_right.json");
  THROW_CHECK(model.ok());
  auto rig = HandRig::Create(*model);
  THROW_CHECK(rig.ok());
  return std::move(rig).value();
}

}  // namespace handdb::testing
