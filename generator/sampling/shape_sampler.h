// Hand-shape samplers (docs/generator.md): `basic` (named shapes), `pairs` (points on the segments
// between pairs of basic shapes), `pca` (Sobol or Gaussian coefficients in a PCA basis of a shape
// set) and `grid` (levels per PCA component). All are deterministic functions of their inputs and
// seed; every sample keeps its joint vector and its sampler coordinates, and samples outside the
// joint limits are clamped (and counted).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "base/status.h"
#include "generator/hand/hand_model.h"

namespace handdb {

struct ShapeSample {
  std::string name;
  JointVector joints{};
  std::vector<double> coeffs;  // pairs: [t]; pca/grid: the component coefficients (before clamping)
  bool clamped = false;        // the joint vector was clamped to the limits
};

// PCA of a set of joint vectors: mean + orthonormal components (columns, by decreasing variance),
// each with its standard deviation. Component signs are fixed (largest-magnitude entry positive)
// so the basis is reproducible.
struct PcaBasis {
  Eigen::VectorXd mean;        // 20
  Eigen::MatrixXd components;  // 20 x k
  Eigen::VectorXd stddev;      // k (population std of the set along each component)
  double explained = 0;        // fraction of the total variance the k components explain
  int num_components() const { return static_cast<int>(components.cols()); }
  JointVector Reconstruct(const std::vector<double>& coeffs) const;
  std::vector<double> Project(const JointVector& joints) const;
};

// kInvalidArgument when k is not in 1..min(20, n-1) or the set has no variance along k components.
Result<PcaBasis> ComputePca(const std::vector<JointVector>& set, int k);

// The named shapes, optionally a subset by name (in the order given; unknown name ->
// kInvalidArgument) or the first `count` (0: all).
Result<std::vector<ShapeSample>> SampleBasic(const std::vector<NamedShape>& library,
                                             const std::vector<std::string>& names,
                                             uint32_t count);

// For every pair i < j of `basic`, `k` points at t = m / (k + 1), m = 1..k, on the segment
// (1-t) a_i + t a_j; with include_endpoints the basic shapes themselves come first.
std::vector<ShapeSample> SamplePairs(const std::vector<ShapeSample>& basic,
                                     int k,
                                     bool include_endpoints);

enum class CoefficientSampling { kSobol, kGaussian };

struct PcaSamplerOptions {
  uint32_t count = 0;  // number of samples
  CoefficientSampling sampling = CoefficientSampling::kSobol;
  double scale = 1.0;  // coefficients are scale * stddev * z, z standard normal (or Sobol mapped)
  double max_sigma = 3.0;  // |z| is truncated to this (0: no truncation)
  uint64_t seed = 0;
  bool Check() const;
};

// Sobol: point i+1 of a digitally shifted Sobol sequence (shift from the seed) mapped through the
// inverse normal CDF; Gaussian: z from Rng(DeriveSeed(seed, kShapeStream, i)). `clamped` counts
// samples that had to be clamped to the limits.
std::vector<ShapeSample> SamplePca(const PcaBasis& basis,
                                   const PcaSamplerOptions& options,
                                   const JointLimits& limits,
                                   uint64_t* clamped);

// The full grid over the components: component c takes levels[c] values evenly spaced in
// [-span, +span] * stddev_c (one level: 0). Row-major, last component fastest.
Result<std::vector<ShapeSample>> SampleGrid(const PcaBasis& basis,
                                            const std::vector<int>& levels,
                                            double span,
                                            const JointLimits& limits,
                                            uint64_t* clamped);

}  // namespace handdb
