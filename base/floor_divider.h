// Exact floor(x / d) for a divisor fixed ahead of many divisions, by one 64 x 64 -> 128 bit
// multiply instead of a 64-bit divide (~40 cycles on the machines we run on). The search divides
// every (view, roll) pair's integer bound sum by the query's or the view's point count: ~4
// million divides per query on a 1M-view database.
//
// Why it is exact: with m = ceil(2^64 / d) = 2^64 / d + e, 0 <= e < 1, the estimate is
// floor(x m / 2^64) = floor(x / d + x e / 2^64), and for x < 2^32 the added term is below
// 2^-32 < 1 / d (d < 2^32), while x / d is at least 1 / d below the next integer. Larger x fall
// back to the divide.
#pragma once

#include <cstdint>

#include "base/status.h"

namespace handdb {

class FloorDivider {
#ifdef __SIZEOF_INT128__
  __extension__ typedef unsigned __int128 Wide;  // GCC and Clang; -Wpedantic knows no __int128
#endif

 public:
  explicit FloorDivider(uint64_t d = 1) : d_(d), m_(d > 1 ? ~uint64_t{0} / d + 1 : 0) {
    THROW_CHECK_GT(d, 0u);
  }
  uint64_t divisor() const { return d_; }
  uint64_t operator()(uint64_t x) const {
    if (d_ == 1) return x;
#ifdef __SIZEOF_INT128__
    if (x >> 32 != 0 || d_ >> 32 != 0) return x / d_;
    return static_cast<uint64_t>((static_cast<Wide>(x) * m_) >> 64);
#else
    return x / d_;
#endif
  }

 private:
  uint64_t d_;
  uint64_t m_;  // ceil(2^64 / d) for d > 1
};

}  // namespace handdb
