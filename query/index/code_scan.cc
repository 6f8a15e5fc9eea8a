#include "query/index/code_scan.h"

#include <cmath>

#include "query/simd.h"

namespace handdb {
namespace {

void ScalarInnerProducts(
    const float* w, int nq, const float* codes, size_t blocks, int dims, float* out) {
  const size_t stride = blocks * kCodeLanes;
  for (size_t b = 0; b < blocks; ++b) {
    const float* block = codes + b * static_cast<size_t>(dims) * kCodeLanes;
    for (int q = 0; q < nq; ++q) {
      const float* wq = w + static_cast<size_t>(q) * dims;
      float acc[kCodeLanes] = {};
      for (int j = 0; j < dims; ++j) {
        for (int i = 0; i < kCodeLanes; ++i) {
          acc[i] = std::fma(wq[j], block[j * kCodeLanes + i], acc[i]);
        }
      }
      for (int i = 0; i < kCodeLanes; ++i) out[q * stride + b * kCodeLanes + i] = acc[i];
    }
  }
}

#ifdef HANDDB_HAVE_AVX2_PATH
bool HaveFma() {
  static const bool have = HaveAvx2() && __builtin_cpu_supports("fma") != 0;
  return have;
}

// Q queries x B blocks per step: Q * B accumulators, B code loads and Q broadcasts per
// dimension. Q = 6, B = 2 keeps 12 accumulators in the 16 ymm registers.
template <int Q, int B>
__attribute__((target("avx2,fma"))) inline void Tile(
    const float* w, size_t q0, const float* codes, size_t b0, int dims, size_t stride, float* out) {
  // Fully unrolled (GCC at -O2 kept acc[][] on the stack otherwise: a load and a store around
  // every FMA, a third of the speed).
  __m256 acc[Q][B];
#pragma GCC unroll 8
  for (int q = 0; q < Q; ++q) {
#pragma GCC unroll 2
    for (int b = 0; b < B; ++b) acc[q][b] = _mm256_setzero_ps();
  }
  const size_t block_floats = static_cast<size_t>(dims) * kCodeLanes;
  const float* block = codes + b0 * block_floats;
  const float* wrow = w + q0 * static_cast<size_t>(dims);
  for (int j = 0; j < dims; ++j) {
    __m256 z[B];
#pragma GCC unroll 2
    for (int b = 0; b < B; ++b) z[b] = _mm256_loadu_ps(block + b * block_floats + j * kCodeLanes);
#pragma GCC unroll 8
    for (int q = 0; q < Q; ++q) {
      const __m256 wq = _mm256_broadcast_ss(wrow + q * static_cast<size_t>(dims) + j);
#pragma GCC unroll 2
      for (int b = 0; b < B; ++b) acc[q][b] = _mm256_fmadd_ps(wq, z[b], acc[q][b]);
    }
  }
#pragma GCC unroll 8
  for (int q = 0; q < Q; ++q) {
#pragma GCC unroll 2
    for (int b = 0; b < B; ++b) {
      _mm256_storeu_ps(out + (q0 + q) * stride + (b0 + b) * kCodeLanes, acc[q][b]);
    }
  }
}

template <int Q>
__attribute__((target("avx2,fma"))) void Rows(
    const float* w, size_t q0, const float* codes, size_t blocks, int dims, float* out) {
  const size_t stride = blocks * kCodeLanes;
  size_t b = 0;
  for (; b + 2 <= blocks; b += 2) Tile<Q, 2>(w, q0, codes, b, dims, stride, out);
  if (b < blocks) Tile<Q, 1>(w, q0, codes, b, dims, stride, out);
}

__attribute__((target("avx2,fma"))) void Avx2InnerProducts(
    const float* w, int nq, const float* codes, size_t blocks, int dims, float* out) {
  size_t q = 0;
  const size_t n = static_cast<size_t>(nq);
  for (; q + 6 <= n; q += 6) Rows<6>(w, q, codes, blocks, dims, out);
  switch (n - q) {
    case 5:
      Rows<5>(w, q, codes, blocks, dims, out);
      break;
    case 4:
      Rows<4>(w, q, codes, blocks, dims, out);
      break;
    case 3:
      Rows<3>(w, q, codes, blocks, dims, out);
      break;
    case 2:
      Rows<2>(w, q, codes, blocks, dims, out);
      break;
    case 1:
      Rows<1>(w, q, codes, blocks, dims, out);
      break;
    default:
      break;
  }
}

// The first block of 8 from `from` holding a value >= floor: the index of that value, or the
// start of the last partial block (which the caller scans) when no full block holds one.
__attribute__((target("avx2"))) size_t NextAtLeastAvx2(const float* values,
                                                       size_t from,
                                                       size_t count,
                                                       float floor) {
  const __m256 f = _mm256_set1_ps(floor);
  size_t i = from;
  for (; i + 8 <= count; i += 8) {
    const int mask = _mm256_movemask_ps(_mm256_cmp_ps(_mm256_loadu_ps(values + i), f, _CMP_GE_OQ));
    if (mask != 0) return i + static_cast<size_t>(__builtin_ctz(static_cast<unsigned>(mask)));
  }
  return i;
}
#endif

}  // namespace

size_t NextAtLeast(const float* values, size_t from, size_t count, float floor) {
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveAvx2()) from = NextAtLeastAvx2(values, from, count, floor);
#endif
  for (size_t i = from; i < count; ++i) {
    if (values[i] >= floor) return i;
  }
  return count;
}

void CodeInnerProducts(
    const float* w, int nq, const float* codes, size_t blocks, int dims, float* out) {
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveFma()) {
    Avx2InnerProducts(w, nq, codes, blocks, dims, out);
    return;
  }
#endif
  ScalarInnerProducts(w, nq, codes, blocks, dims, out);
}

}  // namespace handdb
