#include "generator/sampling/shape_sampler.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

namespace handdb {
namespace {

struct Library {
  HandModel model;
  std::vector<NamedShape> shapes;
  std::vector<JointVector> joints;
};

const Library& Shipped() {
  static const Library lib = [] {
    Library l;
    auto model = LoadHandModel(RepoRoot() / "configs/hands/webxr_generic_right.json");
    THROW_CHECK(model.ok());
    l.model = *model;
    auto shapes = LoadShapes(RepoRoot() / "configs/shapes/basic.json", l.model.limits());
    THROW_CHECK(shapes.ok());
    l.shapes = *shapes;
    for (const auto& s : l.shapes) l.joints.push_back(s.joints);
    return l;
  }();
  return lib;
}

TEST(ShapeSampler, BasicByNameAndCount) {
  auto all = SampleBasic(Shipped().shapes, {}, 0);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->size(), Shipped().shapes.size());
  auto first = SampleBasic(Shipped().shapes, {}, 3);
  ASSERT_TRUE(first.ok());
  ASSERT_EQ(first->size(), 3u);
  EXPECT_EQ((*first)[2].name, Shipped().shapes[2].name);
  auto named = SampleBasic(Shipped().shapes, {"fist", "flat"}, 0);
  ASSERT_TRUE(named.ok());
  ASSERT_EQ(named->size(), 2u);
  EXPECT_EQ((*named)[0].name, "fist");
  EXPECT_FALSE(SampleBasic(Shipped().shapes, {"no-such-shape"}, 0).ok());
  EXPECT_FALSE(SampleBasic(Shipped().shapes, {}, 1000).ok());
}

TEST(ShapeSampler, PairsLieOnSegments) {
  auto basic = SampleBasic(Shipped().shapes, {}, 5);
  ASSERT_TRUE(basic.ok());
  const auto pairs = SamplePairs(*basic, 3, false);
  ASSERT_EQ(pairs.size(), 10u * 3);  // C(5,2) * k
  // The second point of the first pair is the midpoint of shapes 0 and 1.
  EXPECT_DOUBLE_EQ(pairs[1].coeffs[0], 0.5);
  for (int d = 0; d < kNumJointAngles; ++d) {
    EXPECT_NEAR(pairs[1].joints[d], 0.5 * ((*basic)[0].joints[d] + (*basic)[1].joints[d]), 1e-12);
  }
  for (const auto& p : pairs) EXPECT_TRUE(Shipped().model.limits().Contains(p.joints)) << p.name;
  EXPECT_EQ(SamplePairs(*basic, 2, true).size(), 5u + 10u * 2);
}

TEST(ShapeSampler, PcaBasisIsOrthonormalAndOrdered) {
  auto basis = ComputePca(Shipped().joints, 8);
  ASSERT_TRUE(basis.ok()) << basis.status().message();
  const Eigen::MatrixXd gram = basis->components.transpose() * basis->components;
  EXPECT_TRUE(gram.isApprox(Eigen::MatrixXd::Identity(8, 8), 1e-10));
  for (int c = 1; c < 8; ++c) EXPECT_GE(basis->stddev(c - 1), basis->stddev(c));
  EXPECT_GT(basis->explained, 0.5);
  EXPECT_LE(basis->explained, 1.0 + 1e-12);
  // With every component the set has variance along (ComputePca refuses the rest), a shape of
  // the set is reconstructed exactly from its projection.
  int rank = 20;
  while (rank > 0 && !ComputePca(Shipped().joints, rank).ok()) --rank;
  EXPECT_GE(rank, 12);
  auto full = ComputePca(Shipped().joints, rank);
  ASSERT_TRUE(full.ok()) << full.status().message();
  const JointVector& x = Shipped().joints[4];
  const JointVector back = full->Reconstruct(full->Project(x));
  for (int d = 0; d < kNumJointAngles; ++d) EXPECT_NEAR(back[d], x[d], 1e-9);
  EXPECT_FALSE(ComputePca(Shipped().joints, 0).ok());
  EXPECT_FALSE(ComputePca(Shipped().joints, 21).ok());
  EXPECT_FALSE(ComputePca({Shipped().joints[0]}, 1).ok());
}

std::vector<ShapeSample> Pca(CoefficientSampling sampling,
                             uint64_t seed,
                             uint32_t count,
                             uint64_t* clamped) {
  auto basis = ComputePca(Shipped().joints, 6);
  THROW_CHECK(basis.ok());
  PcaSamplerOptions o;
  o.count = count;
  o.sampling = sampling;
  o.seed = seed;
  return SamplePca(*basis, o, Shipped().model.limits(), clamped);
}

TEST(ShapeSampler, PcaIsDeterministicPerSeedAndRespectsLimits) {
  for (auto sampling : {CoefficientSampling::kSobol, CoefficientSampling::kGaussian}) {
    uint64_t clamped_a = 0, clamped_b = 0, clamped_c = 0;
    const auto a = Pca(sampling, 0, 200, &clamped_a);
    const auto b = Pca(sampling, 0, 200, &clamped_b);
    const auto c = Pca(sampling, 1, 200, &clamped_c);
    ASSERT_EQ(a.size(), 200u);
    uint64_t differ = 0, counted = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].joints, b[i].joints);
      EXPECT_EQ(a[i].coeffs, b[i].coeffs);
      differ += a[i].joints != c[i].joints ? 1 : 0;
      EXPECT_TRUE(Shipped().model.limits().Contains(a[i].joints, 0.0)) << a[i].name;
      EXPECT_EQ(a[i].coeffs.size(), 6u);
      counted += a[i].clamped ? 1 : 0;
    }
    EXPECT_EQ(clamped_a, clamped_b);
    EXPECT_EQ(clamped_a, counted);
    EXPECT_GT(differ, 190u);  // seed 0 and seed 1 are different seeds
    // A PCA basis of shapes that sit on the limits must clamp some samples, but not all.
    EXPECT_GT(clamped_a, 0u);
    EXPECT_LT(clamped_a, 200u);
  }
}

TEST(ShapeSampler, SobolCoefficientsFollowTheComponentSpread) {
  auto basis = ComputePca(Shipped().joints, 4);
  ASSERT_TRUE(basis.ok());
  PcaSamplerOptions o;
  o.count = 4096;
  o.max_sigma = 0;  // no truncation: the coefficients are exactly N(0, stddev^2) quantiles
  const auto samples = SamplePca(*basis, o, Shipped().model.limits(), nullptr);
  for (int c = 0; c < 4; ++c) {
    double sum = 0, sum2 = 0;
    for (const auto& s : samples) {
      sum += s.coeffs[c];
      sum2 += s.coeffs[c] * s.coeffs[c];
    }
    const double mean = sum / samples.size();
    const double sd = std::sqrt(sum2 / samples.size() - mean * mean);
    EXPECT_NEAR(mean, 0.0, 0.02 * basis->stddev(c)) << c;
    EXPECT_NEAR(sd, basis->stddev(c), 0.03 * basis->stddev(c)) << c;
  }
}

TEST(ShapeSampler, GridEnumeratesLevels) {
  auto basis = ComputePca(Shipped().joints, 3);
  ASSERT_TRUE(basis.ok());
  uint64_t clamped = 0;
  auto grid = SampleGrid(*basis, {3, 1, 2}, 2.0, Shipped().model.limits(), &clamped);
  ASSERT_TRUE(grid.ok());
  ASSERT_EQ(grid->size(), 6u);
  EXPECT_NEAR((*grid)[0].coeffs[0], -2.0 * basis->stddev(0), 1e-12);
  EXPECT_NEAR((*grid)[5].coeffs[0], 2.0 * basis->stddev(0), 1e-12);
  EXPECT_EQ((*grid)[0].coeffs[1], 0.0);  // a single level is the mean
  EXPECT_NEAR((*grid)[1].coeffs[2], 2.0 * basis->stddev(2), 1e-12);
  std::set<std::vector<double>> distinct;
  for (const auto& s : *grid) {
    distinct.insert(s.coeffs);
    EXPECT_TRUE(Shipped().model.limits().Contains(s.joints, 0.0));
  }
  EXPECT_EQ(distinct.size(), 6u);
  EXPECT_FALSE(SampleGrid(*basis, {3, 3}, 2.0, Shipped().model.limits(), nullptr).ok());
  EXPECT_FALSE(SampleGrid(*basis, {3, 0, 3}, 2.0, Shipped().model.limits(), nullptr).ok());
}

TEST(ShapeSampler, OptionsCheck) {
  PcaSamplerOptions o;
  EXPECT_FALSE(o.Check());  // count 0
  o.count = 1;
  EXPECT_TRUE(o.Check());
  o.scale = 0;
  EXPECT_FALSE(o.Check());
}

}  // namespace
}  // namespace handdb
