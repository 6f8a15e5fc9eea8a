// Deterministic randomness for sampling. Everything random in a plan derives from the config's
// seed through DeriveSeed(seed, stream_or_unit, index), so any item can be regenerated alone and
// seed 0 is an ordinary seed (never "unset"). The generators are specified here (SplitMix64,
// xoshiro256**, Box-Muller, Acklam's inverse normal CDF) rather than taken from <random>, whose
// distributions differ between standard libraries: plans must be byte-identical everywhere.
#pragma once

#include <cstdint>

namespace handdb {

// One SplitMix64 step: a bijective 64-bit mixer.
uint64_t SplitMix64(uint64_t x);

// The seed of item `index` of `stream` (a unit id, or a sampler's stream tag) under `seed`.
uint64_t DeriveSeed(uint64_t seed, uint64_t stream, uint64_t index);

// Stream tags for the samplers (distinct from any plausible unit id).
constexpr uint64_t kShapeStream = 0x5348415045000000ull;       // "SHAPE"
constexpr uint64_t kSobolShiftStream = 0x534f424f4c000000ull;  // "SOBOL"

// xoshiro256** seeded through SplitMix64.
class Rng {
 public:
  explicit Rng(uint64_t seed);
  uint64_t Next();
  double Uniform();  // [0, 1), 53 random bits
  double Normal();  // standard normal (Box-Muller, no cached second value: stateless per call pair)

 private:
  uint64_t s_[4];
};

// Inverse of the standard normal CDF for p in (0, 1) (Acklam's rational approximation refined by
// one Halley step: |error| < 1e-12). Throws (THROW_CHECK) outside (0, 1).
double InverseNormalCdf(double p);

}  // namespace handdb
