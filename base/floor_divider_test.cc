#include "base/floor_divider.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <random>

namespace handdb {
namespace {

TEST(FloorDividerTest, MatchesDivisionOnEdgesAndRandomValues) {
  std::mt19937_64 rng(7);
  const uint64_t divisors[] = {1,
                               2,
                               3,
                               5,
                               7,
                               64,
                               100,
                               641,
                               755,
                               1023,
                               1024,
                               1025,
                               65535,
                               65536,
                               4294967295ULL,
                               4294967296ULL,
                               0xFFFFFFFFFFFFFFFFULL};
  for (uint64_t d : divisors) {
    const FloorDivider div(d);
    // Multiples of d and their neighbours, where a rounded-up estimate would show.
    for (uint64_t k : {0ULL, 1ULL, 2ULL, 1000ULL, 4294967295ULL / d, 4294967296ULL / d}) {
      for (int64_t delta : {-1, 0, 1}) {
        const uint64_t x = k * d + static_cast<uint64_t>(delta);
        if (delta < 0 && k == 0) continue;
        EXPECT_EQ(div(x), x / d) << x << " / " << d;
      }
    }
    for (uint64_t x : {0ULL, 1ULL, 4294967295ULL, 4294967296ULL, 0xFFFFFFFFFFFFFFFFULL}) {
      EXPECT_EQ(div(x), x / d) << x << " / " << d;
    }
    for (int i = 0; i < 20000; ++i) {
      const uint64_t x = rng() >> (rng() % 64);
      ASSERT_EQ(div(x), x / d) << x << " / " << d;
    }
  }
  for (int i = 0; i < 200000; ++i) {
    const uint64_t d = 1 + (rng() >> (33 + rng() % 31));
    const uint64_t x = rng() >> 32;
    ASSERT_EQ(FloorDivider(d)(x), x / d) << x << " / " << d;
  }
}

TEST(FloorDividerTest, RejectsZero) { EXPECT_THROW(FloorDivider(0), std::exception); }

}  // namespace
}  // namespace handdb
