#include "base/hex.h"

#include <gtest/gtest.h>

#include <cinttypes>
#include <cstdio>

namespace handdb {
namespace {

TEST(Hex, PrefixedMatchesPrintf) {
  for (uint64_t v : {uint64_t{0},
                     uint64_t{1},
                     uint64_t{0xff},
                     uint64_t{0x8000000000000000},
                     ~uint64_t{0},
                     uint64_t{0x123456789abcdef0}}) {
    char buf[24];
    std::snprintf(buf, sizeof(buf), "0x%" PRIx64, v);
    EXPECT_EQ(HexPrefixed(v), buf) << v;
  }
}

TEST(Hex, Hex64IsZeroPaddedTo16Digits) {
  EXPECT_EQ(Hex64(0), "0000000000000000");
  EXPECT_EQ(Hex64(0xabc), "0000000000000abc");
  EXPECT_EQ(Hex64(0xfedcba9876543210), "fedcba9876543210");
}

TEST(Hex, BytesInMemoryOrderWithSeparator) {
  const uint8_t bytes[] = {0x68, 0x64, 0x00, 0xff};
  EXPECT_EQ(HexBytes(bytes, 4), "686400ff");
  EXPECT_EQ(HexBytes(bytes, 4, " "), "68 64 00 ff");
  EXPECT_EQ(HexBytes(bytes, 0, " "), "");
}

}  // namespace
}  // namespace handdb
