// "Natural" hand poses for test sets (docs/evaluation.md, "Natural poses"): a sampler that needs
// neither a shape library nor a PCA basis, so a test set drawn with it shares nothing with the
// shapes a database was made from.
//
// A hand at rest curls its fingers together, so flexions are correlated through one grip level
// g ~ U[0, 1] per pose. Finger f (the thumb and the four fingers, DOF order of
// docs/conventions.md) gets its own level g_f = g + finger_spread * z_f (z_f standard normal), and
// each of its flexion DOFs k is rest_k + g_f * (max_k - rest_k), where rest_k is the straight
// joint (0, clamped to the limits): g = 0 is a flat hand, g = 1 a fist. Each abduction DOF is
// rest_k + abduction_spread * z_k * (max_k - min_k) / 2. Everything is clamped to the hand model's
// limits. Sample i draws, from Rng(DeriveSeed(seed, kNaturalPoseStream, i)), g, then z_f for the
// five fingers, then z_k for the five abduction DOFs, so any sample can be regenerated alone.
#pragma once

#include <array>
#include <cstdint>

#include "format/view.h"

namespace handdb {

constexpr uint64_t kNaturalPoseStream = 0x4e41545552000000ull;  // "NATUR"

constexpr int kNumFingers = 5;  // thumb, index, middle, ring, pinky

struct NaturalPoseOptions {
  double finger_spread = 0.15;     // std of a finger's level around g, in units of its range
  double abduction_spread = 0.25;  // std of an abduction, in units of half its range
  uint64_t seed = 0;
  bool Check() const;
};

struct NaturalPose {
  JointVector joints{};
  double grip = 0;                                // g
  std::array<double, kNumFingers> finger_grip{};  // g_f before clamping
  bool clamped = false;                           // some DOF was clamped to the limits
};

// The flexion DOFs of finger f (0 = thumb) in DOF order, and its abduction DOF.
std::array<int, 3> FingerFlexionDofs(int finger);
int FingerAbductionDof(int finger);

// Sample `index` of the natural-pose stream of options.seed.
NaturalPose SampleNaturalPose(const NaturalPoseOptions& options,
                              const JointLimits& limits,
                              uint64_t index);

}  // namespace handdb
