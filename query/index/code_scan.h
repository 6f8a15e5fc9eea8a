// Inner products of rolled query vectors with an index's codes, for the filter of indexed search
// (query/index/view_index.h). The codes are stored in blocks of kCodeLanes views, dimension-major
// within a block (block b, dimension j, lane i at codes[(b * dims + j) * kCodeLanes + i]), so one
// pass over a block serves every query at once: at 96 rolled queries (both hands) the filter is a
// small matrix product, bound by arithmetic rather than by memory, instead of 96 single-query
// scans of the same codes (docs/index.md, "The exhaustive filter").
#pragma once

#include <cstddef>

namespace handdb {

constexpr int kCodeLanes = 8;

// out[q * blocks * kCodeLanes + b * kCodeLanes + i] = sum_j w[q * dims + j] * codes[block b,
// dimension j, lane i], summed in order of j with one fused multiply-add per term (so the AVX2
// kernel and the scalar fallback give the same floats), for q in [0, nq) and b in [0, blocks).
void CodeInnerProducts(
    const float* w, int nq, const float* codes, size_t blocks, int dims, float* out);

// The first i in [from, count) with values[i] >= floor, or count: the filter's test of a row of
// inner products against the worst candidate kept, 8 at a time.
size_t NextAtLeast(const float* values, size_t from, size_t count, float floor);

}  // namespace handdb
