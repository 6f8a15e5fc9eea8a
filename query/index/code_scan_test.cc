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

}  // namespace
}  // namespace handdb
