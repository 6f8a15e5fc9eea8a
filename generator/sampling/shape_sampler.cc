#include "generator/sampling/shape_sampler.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>

#include "generator/sampling/random.h"
#include "generator/sampling/sobol.h"

namespace handdb {
namespace {

std::string Numbered(const char* prefix, uint64_t i) {
  char buf[48];
  std::snprintf(buf, sizeof(buf), "%s-%05llu", prefix, static_cast<unsigned long long>(i));
  return buf;
}

}  // namespace

JointVector PcaBasis::Reconstruct(const std::vector<double>& coeffs) const {
  THROW_CHECK_EQ(coeffs.size(), static_cast<size_t>(num_components()));
  Eigen::VectorXd x = mean;
  for (int c = 0; c < num_components(); ++c)
    x += coeffs[static_cast<size_t>(c)] * components.col(c);
  JointVector out;
  for (int i = 0; i < kNumJointAngles; ++i) out[i] = x(i);
  return out;
}

std::vector<double> PcaBasis::Project(const JointVector& joints) const {
  Eigen::VectorXd x(kNumJointAngles);
  for (int i = 0; i < kNumJointAngles; ++i) x(i) = joints[i];
  const Eigen::VectorXd c = components.transpose() * (x - mean);
  return std::vector<double>(c.data(), c.data() + c.size());
}

Result<PcaBasis> ComputePca(const std::vector<JointVector>& set, int k) {
  const int n = static_cast<int>(set.size());
  if (n < 2) {
    return Status(StatusCode::kInvalidArgument,
                  "PCA needs at least 2 shapes, got " + std::to_string(n));
  }
  const int max_k = std::min(kNumJointAngles, n - 1);
  if (k < 1 || k > max_k) {
    return Status(StatusCode::kInvalidArgument,
                  "PCA components " + std::to_string(k) + " not in 1.." + std::to_string(max_k) +
                      " for " + std::to_string(n) + " shapes");
  }
  Eigen::MatrixXd x(n, kNumJointAngles);
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < kNumJointAngles; ++c) x(r, c) = set[static_cast<size_t>(r)][c];
  }
  PcaBasis basis;
  basis.mean = x.colwise().mean().transpose();
  const Eigen::MatrixXd centred = x.rowwise() - basis.mean.transpose();
  const Eigen::MatrixXd cov = centred.transpose() * centred / static_cast<double>(n);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(cov);
  if (eig.info() != Eigen::Success) {
    return Status(StatusCode::kInvalidArgument, "PCA: eigen decomposition failed");
  }
  // Eigen sorts ascending; take the k largest.
  const Eigen::VectorXd values = eig.eigenvalues();
  const double total = std::max(values.sum(), 0.0);
  basis.components.resize(kNumJointAngles, k);
  basis.stddev.resize(k);
  double kept = 0;
  for (int c = 0; c < k; ++c) {
    const int src = kNumJointAngles - 1 - c;
    Eigen::VectorXd v = eig.eigenvectors().col(src);
    Eigen::Index arg = 0;
    v.cwiseAbs().maxCoeff(&arg);
    if (v(arg) < 0) v = -v;
    basis.components.col(c) = v;
    const double var = std::max(values(src), 0.0);
    if (!(var > 1e-12 * std::max(total, 1e-300))) {
      return Status(StatusCode::kInvalidArgument,
                    "PCA: the shape set has no variance along component " + std::to_string(c + 1) +
                        " (use fewer components)");
    }
    basis.stddev(c) = std::sqrt(var);
    kept += var;
  }
  basis.explained = total > 0 ? kept / total : 0;
  return basis;
}

Result<std::vector<ShapeSample>> SampleBasic(const std::vector<NamedShape>& library,
                                             const std::vector<std::string>& names,
                                             uint32_t count) {
  std::vector<ShapeSample> out;
  auto add = [&](const NamedShape& s) { out.push_back(ShapeSample{s.name, s.joints, {}, false}); };
  if (!names.empty()) {
    std::map<std::string, const NamedShape*> by_name;
    for (const auto& s : library) by_name[s.name] = &s;
    for (const auto& name : names) {
      auto it = by_name.find(name);
      if (it == by_name.end()) {
        return Status(StatusCode::kInvalidArgument, "unknown basic shape '" + name + "'");
      }
      add(*it->second);
    }
  } else {
    if (count > library.size()) {
      return Status(StatusCode::kInvalidArgument,
                    "count " + std::to_string(count) + " exceeds the " +
                        std::to_string(library.size()) + " basic shapes");
    }
    const size_t n = count == 0 ? library.size() : count;
    for (size_t i = 0; i < n; ++i) add(library[i]);
  }
  return out;
}

std::vector<ShapeSample> SamplePairs(const std::vector<ShapeSample>& basic,
                                     int k,
                                     bool include_endpoints) {
  THROW_CHECK_GE(k, 1);
  std::vector<ShapeSample> out;
  if (include_endpoints) {
    for (const auto& b : basic) out.push_back(ShapeSample{b.name, b.joints, {0.0}, false});
  }
  for (size_t i = 0; i < basic.size(); ++i) {
    for (size_t j = i + 1; j < basic.size(); ++j) {
      for (int m = 1; m <= k; ++m) {
        const double t = static_cast<double>(m) / (k + 1);
        ShapeSample s;
        s.name = basic[i].name + "~" + basic[j].name + "@" + std::to_string(m) + "/" +
                 std::to_string(k + 1);
        for (int d = 0; d < kNumJointAngles; ++d)
          s.joints[d] = (1 - t) * basic[i].joints[d] + t * basic[j].joints[d];
        s.coeffs = {t};
        out.push_back(std::move(s));
      }
    }
  }
  return out;
}

bool PcaSamplerOptions::Check() const {
  CHECK_OPTION_GT(count, 0u);
  CHECK_OPTION_GT(scale, 0.0);
  CHECK_OPTION_GE(max_sigma, 0.0);
  return true;
}

std::vector<ShapeSample> SamplePca(const PcaBasis& basis,
                                   const PcaSamplerOptions& options,
                                   const JointLimits& limits,
                                   uint64_t* clamped) {
  THROW_CHECK(options.Check());
  const int k = basis.num_components();
  std::vector<ShapeSample> out;
  out.reserve(options.count);
  uint64_t n_clamped = 0;
  std::unique_ptr<Sobol> sobol;
  std::vector<uint32_t> shift;
  if (options.sampling == CoefficientSampling::kSobol) {
    THROW_CHECK_LE(k, Sobol::kMaxDims);
    sobol = std::make_unique<Sobol>(k);
    Rng rng(DeriveSeed(options.seed, kSobolShiftStream, 0));
    for (int c = 0; c < k; ++c) shift.push_back(static_cast<uint32_t>(rng.Next() >> 32));
  }
  for (uint32_t i = 0; i < options.count; ++i) {
    std::vector<double> z(static_cast<size_t>(k));
    if (sobol) {
      // Index i + 1 skips the origin, the one point the shift maps to a corner pattern.
      const std::vector<double> u = sobol->ShiftedPoint(uint64_t{i} + 1, shift);
      for (int c = 0; c < k; ++c) z[c] = InverseNormalCdf(u[c]);
    } else {
      Rng rng(DeriveSeed(options.seed, kShapeStream, i));
      for (int c = 0; c < k; ++c) z[c] = rng.Normal();
    }
    ShapeSample s;
    s.name = Numbered("pca", i);
    s.coeffs.resize(static_cast<size_t>(k));
    for (int c = 0; c < k; ++c) {
      double zc = z[c];
      if (options.max_sigma > 0) zc = std::clamp(zc, -options.max_sigma, options.max_sigma);
      s.coeffs[c] = options.scale * basis.stddev(c) * zc;
    }
    s.joints = basis.Reconstruct(s.coeffs);
    s.clamped = limits.Clamp(&s.joints);
    n_clamped += s.clamped ? 1 : 0;
    out.push_back(std::move(s));
  }
  if (clamped != nullptr) *clamped = n_clamped;
  return out;
}

Result<std::vector<ShapeSample>> SampleGrid(const PcaBasis& basis,
                                            const std::vector<int>& levels,
                                            double span,
                                            const JointLimits& limits,
                                            uint64_t* clamped) {
  const int k = basis.num_components();
  if (static_cast<int>(levels.size()) != k) {
    return Status(StatusCode::kInvalidArgument,
                  "grid: " + std::to_string(levels.size()) + " level counts for " +
                      std::to_string(k) + " components");
  }
  uint64_t total = 1;
  for (int l : levels) {
    if (l < 1) return Status(StatusCode::kInvalidArgument, "grid: levels must be >= 1");
    total *= static_cast<uint64_t>(l);
    if (total > 10'000'000) {
      return Status(StatusCode::kInvalidArgument, "grid: more than 10,000,000 shapes");
    }
  }
  if (!(span > 0)) return Status(StatusCode::kInvalidArgument, "grid: span must be > 0");
  std::vector<ShapeSample> out;
  out.reserve(total);
  uint64_t n_clamped = 0;
  std::vector<int> idx(static_cast<size_t>(k), 0);
  for (uint64_t i = 0; i < total; ++i) {
    // Decode i into per-component level indices, last component fastest.
    uint64_t rest = i;
    for (int c = k - 1; c >= 0; --c) {
      idx[c] = static_cast<int>(rest % static_cast<uint64_t>(levels[c]));
      rest /= static_cast<uint64_t>(levels[c]);
    }
    ShapeSample s;
    s.name = Numbered("grid", i);
    s.coeffs.resize(static_cast<size_t>(k));
    for (int c = 0; c < k; ++c) {
      const double z = levels[c] == 1 ? 0.0 : -span + 2.0 * span * idx[c] / (levels[c] - 1);
      s.coeffs[c] = z * basis.stddev(c);
    }
    s.joints = basis.Reconstruct(s.coeffs);
    s.clamped = limits.Clamp(&s.joints);
    n_clamped += s.clamped ? 1 : 0;
    out.push_back(std::move(s));
  }
  if (clamped != nullptr) *clamped = n_clamped;
  return out;
}

}  // namespace handdb
