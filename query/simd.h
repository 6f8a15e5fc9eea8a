// Runtime dispatch to the AVX2 kernels of the query module (distance transform, bound lookups,
// linear nearest-point scans). Kernels are compiled with __attribute__((target("avx2"))) inside
// `#ifdef HANDDB_HAVE_AVX2_PATH` and called only when HaveAvx2(); every kernel has a scalar
// fallback that gives the same values. HANDDB_SCALAR_KERNELS=1 in the environment selects the
// fallbacks on any CPU: the tests run the query module's suites once more with it
// (query/CMakeLists.txt), so the code a CPU without AVX2 (or a non-x86 build) runs is tested on
// every machine, and a suspected kernel bug can be checked against the plain code.
#pragma once

#include <cstdlib>
#include <cstring>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define HANDDB_HAVE_AVX2_PATH 1
#endif

namespace handdb {

#ifdef HANDDB_HAVE_AVX2_PATH
// True if this CPU runs AVX2 (checked once).
inline bool HaveAvx2() {
  static const bool have = [] {
    const char* scalar = std::getenv("HANDDB_SCALAR_KERNELS");
    if (scalar != nullptr && std::strcmp(scalar, "1") == 0) return false;
    return __builtin_cpu_supports("avx2") != 0;
  }();
  return have;
}
#endif

}  // namespace handdb
