#include "generator/sampling/sobol.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <vector>

#include "generator/sampling/random.h"

namespace handdb {
namespace {

TEST(Sobol, FirstPointsMatchTheReferenceSequence) {
  // The unscrambled 2-D Sobol' sequence (Joe-Kuo; identical in SciPy's qmc.Sobol(scramble=False)).
  const double expected[8][2] = {{0, 0},
                                 {0.5, 0.5},
                                 {0.75, 0.25},
                                 {0.25, 0.75},
                                 {0.375, 0.375},
                                 {0.875, 0.875},
                                 {0.625, 0.125},
                                 {0.125, 0.625}};
  Sobol sobol(2);
  for (int i = 0; i < 8; ++i) {
    const auto p = sobol.Point(static_cast<uint64_t>(i));
    EXPECT_EQ(p[0], expected[i][0]) << i;
    EXPECT_EQ(p[1], expected[i][1]) << i;
  }
  // Third dimension (s=2, a=1, m=1,3): 0, 1/2, 1/4, 3/4, 5/8, 1/8, 7/8, 3/8.
  const double third[8] = {0, 0.5, 0.25, 0.75, 0.625, 0.125, 0.875, 0.375};
  Sobol sobol3(3);
  for (int i = 0; i < 8; ++i) EXPECT_EQ(sobol3.Point(static_cast<uint64_t>(i))[2], third[i]) << i;
}

TEST(Sobol, EveryDimensionIsStratified) {
  // The first 2^m points of each coordinate hit every interval [j/2^m, (j+1)/2^m) exactly once.
  Sobol sobol(Sobol::kMaxDims);
  constexpr int kM = 10;
  std::vector<std::vector<int>> hits(Sobol::kMaxDims, std::vector<int>(1 << kM, 0));
  for (uint64_t i = 0; i < (1u << kM); ++i) {
    const auto p = sobol.Point(i);
    for (int d = 0; d < Sobol::kMaxDims; ++d) ++hits[d][static_cast<int>(p[d] * (1 << kM))];
  }
  for (int d = 0; d < Sobol::kMaxDims; ++d) {
    for (int j = 0; j < (1 << kM); ++j) ASSERT_EQ(hits[d][j], 1) << "dim " << d << " cell " << j;
  }
}

TEST(Sobol, FirstTwoDimensionsFormA02Net) {
  // 2^m points, every elementary box of area 2^-m (2^a x 2^(m-a) grid) holds exactly one point.
  Sobol sobol(2);
  constexpr int kM = 8;
  for (int a = 0; a <= kM; ++a) {
    std::set<std::pair<int, int>> cells;
    for (uint64_t i = 0; i < (1u << kM); ++i) {
      const auto p = sobol.Point(i);
      cells.emplace(static_cast<int>(p[0] * (1 << a)), static_cast<int>(p[1] * (1 << (kM - a))));
    }
    EXPECT_EQ(cells.size(), 1u << kM) << "a=" << a;
  }
}

TEST(Sobol, ShiftKeepsStratificationAndStaysInsideTheUnitCube) {
  Sobol sobol(5);
  Rng rng(DeriveSeed(0, kSobolShiftStream, 0));
  std::vector<uint32_t> shift;
  for (int d = 0; d < 5; ++d) shift.push_back(static_cast<uint32_t>(rng.Next() >> 32));
  std::vector<std::set<int>> cells(5);
  for (uint64_t i = 0; i < 256; ++i) {
    const auto p = sobol.ShiftedPoint(i, shift);
    for (int d = 0; d < 5; ++d) {
      ASSERT_GT(p[d], 0.0);
      ASSERT_LT(p[d], 1.0);
      cells[d].insert(static_cast<int>(p[d] * 256));
    }
  }
  for (int d = 0; d < 5; ++d) EXPECT_EQ(cells[d].size(), 256u);
}

TEST(Sobol, RejectsBadDimensions) {
  EXPECT_THROW(Sobol(0), std::logic_error);
  EXPECT_THROW(Sobol(Sobol::kMaxDims + 1), std::logic_error);
}

TEST(Random, DerivedSeedsAreDistinctAndSeedZeroIsOrdinary) {
  std::set<uint64_t> seen;
  for (uint64_t seed : {0ull, 1ull, 2ull}) {
    for (uint64_t unit = 0; unit < 20; ++unit) {
      for (uint64_t index = 0; index < 50; ++index) seen.insert(DeriveSeed(seed, unit, index));
    }
  }
  EXPECT_EQ(seen.size(), 3u * 20 * 50);
  EXPECT_NE(DeriveSeed(0, 0, 0), 0u);
  EXPECT_EQ(DeriveSeed(7, 3, 9), DeriveSeed(7, 3, 9));
  EXPECT_NE(DeriveSeed(0, 1, 0), DeriveSeed(0, 0, 1));
}

TEST(Random, NormalHasUnitMoments) {
  Rng rng(0);
  double sum = 0, sum2 = 0;
  constexpr int kN = 200000;
  for (int i = 0; i < kN; ++i) {
    const double x = rng.Normal();
    sum += x;
    sum2 += x * x;
  }
  EXPECT_NEAR(sum / kN, 0.0, 0.01);
  EXPECT_NEAR(sum2 / kN, 1.0, 0.02);
  Rng a(5), b(5);
  for (int i = 0; i < 10; ++i) EXPECT_EQ(a.Next(), b.Next());
}

TEST(Random, InverseNormalCdfKnownValues) {
  EXPECT_NEAR(InverseNormalCdf(0.5), 0.0, 1e-14);
  EXPECT_NEAR(InverseNormalCdf(0.975), 1.959963984540054, 1e-12);
  EXPECT_NEAR(InverseNormalCdf(0.025), -1.959963984540054, 1e-12);
  EXPECT_NEAR(InverseNormalCdf(0.8413447460685429), 1.0, 1e-11);
  EXPECT_NEAR(InverseNormalCdf(1e-10), -6.361340902404056, 1e-9);
  EXPECT_THROW(InverseNormalCdf(0.0), std::logic_error);
  EXPECT_THROW(InverseNormalCdf(1.0), std::logic_error);
}

}  // namespace
}  // namespace handdb
