#include "format/coarse_field.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "format/shard_testing.h"

namespace handdb {
namespace {

using testing::RandomPoints;

uint8_t Units(int64_t d2) {
  return static_cast<uint8_t>(
      std::min(255.0, std::floor(std::sqrt(static_cast<double>(d2)) * 2.0 / kPointScale)));
}

// The envelope computation equals the brute-force box distance in every cell, and the centre
// field the brute-force centre distance: clustered sets, sets wider than the grid, many points
// sharing an x, a single point.
TEST(CoarseField, EqualsBruteForceInEveryCell) {
  std::mt19937 rng(7);
  std::vector<std::vector<PointQ>> sets;
  sets.push_back(RandomPoints(&rng, 600, 1600));
  sets.push_back(RandomPoints(&rng, 300, 4000));  // beyond the grid's 2752 units
  sets.push_back(RandomPoints(&rng, 50, 200));
  sets.push_back({{0, 0}});
  sets.push_back({{-32768, 32767}, {32767, -32768}});
  std::vector<PointQ> column;
  for (int i = 0; i < 200; ++i) column.push_back({128, static_cast<int16_t>(i * 13 - 1300)});
  sets.push_back(column);
  // Raster order (sorted by y), as database views come: the transposed path.
  for (size_t s = 0; s < 2; ++s) {
    std::vector<PointQ> sorted = sets[s];
    std::stable_sort(sorted.begin(), sorted.end(), [](PointQ a, PointQ b) { return a.y < b.y; });
    sets.push_back(sorted);
  }
  std::vector<uint8_t> field(CoarseGrid::kCells);
  std::vector<uint8_t> centre(CoarseGrid::kCells);
  for (size_t s = 0; s < sets.size(); ++s) {
    ComputeCoarseField(sets[s], field.data());
    ComputeCentreField(sets[s], centre.data());
    for (int iy = 0; iy < CoarseGrid::kSide; ++iy) {
      for (int ix = 0; ix < CoarseGrid::kSide; ++ix) {
        const int c = iy * CoarseGrid::kSide + ix;
        const uint8_t want = Units(CoarseCellDistanceSquaredBruteForce(sets[s], ix, iy));
        ASSERT_EQ(field[c], want) << "set " << s << " cell " << ix << "," << iy;
        // The centre field: the same envelope evaluated at the centres; the centre lies in the
        // box and at most half its diagonal (5.66 px, 11.3 half px) from every point of it.
        const uint8_t want_centre = Units(CentreDistanceSquaredBruteForce(sets[s], ix, iy));
        ASSERT_EQ(centre[c], want_centre) << "set " << s << " cell " << ix << "," << iy;
        ASSERT_GE(centre[c], field[c]);
        if (centre[c] < 255) {
          ASSERT_LE(centre[c], field[c] + 12);
        }
      }
    }
  }
  ComputeCentreField({}, centre.data());
  EXPECT_EQ(std::count(centre.begin(), centre.end(), 0), CoarseGrid::kCells);
}

}  // namespace
}  // namespace handdb
