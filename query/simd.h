// Runtime dispatch to the AVX2 kernels of the query module (distance transform, bound lookups,
// linear nearest-point scans). Kernels are compiled with __attribute__((target("avx2"))) inside
// `#ifdef HANDDB_HAVE_AVX2_PATH` and called only when HaveAvx2(); every kernel has a scalar
// fallback that gives the same values.
#pragma once

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define HANDDB_HAVE_AVX2_PATH 1
#endif

namespace handdb {

#ifdef HANDDB_HAVE_AVX2_PATH
// True if this CPU runs AVX2 (checked once).
inline bool HaveAvx2() {
  static const bool have = __builtin_cpu_supports("avx2");
  return have;
}
#endif

}  // namespace handdb
