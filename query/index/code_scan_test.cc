#include "query/index/code_scan.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace handdb {
namespace {

// The kernel in use (AVX2 or, under HANDDB_SCALAR_KERNELS=1, the fallback) against the
// definition: one fused multiply-add per term in order of the dimension, so equal floats.
TEST(CodeInnerProducts, EqualsTheOrderedFusedSumForEveryShape) {
  std::mt19937 rng(7);
  std::normal_distribution<float> g(0.0f, 3.0f);
  for (int dims : {1, 24, 64}) {
    for (int nq : {1, 2, 5, 6, 7, 13, 48}) {
      for (size_t blocks : {1u, 2u, 3u, 8u}) {
        std::vector<float> w(static_cast<size_t>(nq) * dims), codes(blocks * dims * kCodeLanes);
        for (float& x : w) x = g(rng);
        for (float& x : codes) x = g(rng);
        std::vector<float> out(static_cast<size_t>(nq) * blocks * kCodeLanes, -1.0f);
        CodeInnerProducts(w.data(), nq, codes.data(), blocks, dims, out.data());
        for (int q = 0; q < nq; ++q) {
          for (size_t b = 0; b < blocks; ++b) {
            for (int i = 0; i < kCodeLanes; ++i) {
              float want = 0;
              for (int j = 0; j < dims; ++j) {
                want = std::fma(w[static_cast<size_t>(q) * dims + j],
                                codes[(b * dims + j) * kCodeLanes + i],
                                want);
              }
              ASSERT_EQ(out[q * blocks * kCodeLanes + b * kCodeLanes + i], want)
                  << "dims " << dims << " nq " << nq << " blocks " << blocks << " q " << q
                  << " block " << b << " lane " << i;
            }
          }
        }
      }
    }
  }
}

// NextAtLeast against the plain scan, from every start, for lengths around the 8-wide blocks.
TEST(NextAtLeast, EqualsThePlainScan) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (size_t count : {0u, 1u, 7u, 8u, 9u, 16u, 23u, 64u}) {
    std::vector<float> values(count);
    for (float& x : values) x = u(rng);
    for (float floor : {-1.0f, 0.5f, 0.95f, 2.0f}) {
      for (size_t from = 0; from <= count; ++from) {
        size_t want = from;
        while (want < count && values[want] < floor) ++want;
        ASSERT_EQ(NextAtLeast(values.data(), from, count, floor), want)
            << "count " << count << " floor " << floor << " from " << from;
      }
    }
  }
}

}  // namespace
}  // namespace handdb
