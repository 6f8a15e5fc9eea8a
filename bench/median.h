// The median every bench prints (the mean of the two middle values for an even count; NaN for
// none), in a header light enough for any bench.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace handdb::bench {

inline double Median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace handdb::bench
