#include "generator/sampling/natural_pose.h"

#include <algorithm>

#include "base/status.h"
#include "generator/sampling/random.h"

namespace handdb {

bool NaturalPoseOptions::Check() const {
  CHECK_OPTION_GE(finger_spread, 0.0);
  CHECK_OPTION_LE(finger_spread, 1.0);
  CHECK_OPTION_GE(abduction_spread, 0.0);
  CHECK_OPTION_LE(abduction_spread, 1.0);
  return true;
}

std::array<int, 3> FingerFlexionDofs(int finger) {
  THROW_CHECK(finger >= 0 && finger < kNumFingers);
  // Thumb: CMC flexion, (CMC abduction), MCP, IP; fingers: MCP, (MCP abduction), PIP, DIP.
  const int base = 4 * finger;
  return {base, base + 2, base + 3};
}

int FingerAbductionDof(int finger) {
  THROW_CHECK(finger >= 0 && finger < kNumFingers);
  return 4 * finger + 1;
}

NaturalPose SampleNaturalPose(const NaturalPoseOptions& options,
                              const JointLimits& limits,
                              uint64_t index) {
  THROW_CHECK(options.Check());
  Rng rng(DeriveSeed(options.seed, kNaturalPoseStream, index));
  NaturalPose pose;
  pose.grip = rng.Uniform();
  for (int f = 0; f < kNumFingers; ++f) {
    pose.finger_grip[f] = pose.grip + options.finger_spread * rng.Normal();
  }
  std::array<double, kNumFingers> abduction_z{};
  for (double& z : abduction_z) z = rng.Normal();
  auto rest = [&](int k) { return std::clamp(0.0, limits.min[k], limits.max[k]); };
  for (int f = 0; f < kNumFingers; ++f) {
    for (int k : FingerFlexionDofs(f)) {
      pose.joints[k] = rest(k) + pose.finger_grip[f] * (limits.max[k] - rest(k));
    }
    const int a = FingerAbductionDof(f);
    pose.joints[a] =
        rest(a) + options.abduction_spread * abduction_z[f] * 0.5 * (limits.max[a] - limits.min[a]);
  }
  pose.clamped = limits.Clamp(&pose.joints);
  return pose;
}

}  // namespace handdb
