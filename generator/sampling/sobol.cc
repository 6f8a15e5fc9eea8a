#include "generator/sampling/sobol.h"

#include "base/status.h"

namespace handdb {
namespace {

struct JoeKuoRow {
  int s;          // degree of the primitive polynomial
  uint32_t a;     // its interior coefficients a_1..a_{s-1} as bits (a_1 most significant)
  uint32_t m[7];  // initial direction numbers m_1..m_s
};

// Dimensions 2..21 of new-joe-kuo-6.21201 (dimension 1 is the van der Corput sequence).
constexpr JoeKuoRow kJoeKuo[Sobol::kMaxDims - 1] = {
    {1, 0, {1}},
    {2, 1, {1, 3}},
    {3, 1, {1, 3, 1}},
    {3, 2, {1, 1, 1}},
    {4, 1, {1, 1, 3, 3}},
    {4, 4, {1, 3, 5, 13}},
    {5, 2, {1, 1, 5, 5, 17}},
    {5, 4, {1, 1, 5, 5, 5}},
    {5, 7, {1, 1, 7, 11, 19}},
    {5, 11, {1, 1, 5, 1, 1}},
    {5, 13, {1, 1, 1, 3, 11}},
    {5, 14, {1, 3, 5, 5, 31}},
    {6, 1, {1, 3, 3, 9, 7, 49}},
    {6, 13, {1, 1, 1, 15, 21, 21}},
    {6, 16, {1, 3, 1, 13, 27, 49}},
    {6, 19, {1, 1, 1, 15, 7, 5}},
    {6, 22, {1, 3, 1, 15, 13, 25}},
    {6, 25, {1, 1, 5, 5, 19, 61}},
    {7, 1, {1, 3, 7, 11, 23, 15, 103}},
    {7, 4, {1, 3, 7, 13, 13, 15, 69}},
};

}  // namespace

Sobol::Sobol(int dims) : dims_(dims), v_(static_cast<size_t>(dims)) {
  THROW_CHECK_MSG(dims >= 1 && dims <= kMaxDims,
                  "Sobol dims " << dims << " not in 1.." << kMaxDims);
  for (int k = 0; k < kBits; ++k) v_[0][k] = 1u << (kBits - 1 - k);
  for (int d = 1; d < dims; ++d) {
    const JoeKuoRow& row = kJoeKuo[d - 1];
    auto& v = v_[static_cast<size_t>(d)];
    for (int k = 0; k < row.s; ++k) v[k] = row.m[k] << (kBits - 1 - k);
    for (int k = row.s; k < kBits; ++k) {
      v[k] = v[k - row.s] ^ (v[k - row.s] >> row.s);
      for (int j = 1; j < row.s; ++j) {
        if ((row.a >> (row.s - 1 - j)) & 1u) v[k] ^= v[k - j];
      }
    }
  }
}

void Sobol::PointBits(uint64_t index, uint32_t* out) const {
  THROW_CHECK_MSG(index < (uint64_t{1} << kBits), "Sobol index " << index << " beyond 2^32");
  const uint64_t gray = index ^ (index >> 1);
  for (int d = 0; d < dims_; ++d) {
    uint32_t x = 0;
    for (int k = 0; k < kBits; ++k) {
      if ((gray >> k) & 1u) x ^= v_[static_cast<size_t>(d)][k];
    }
    out[d] = x;
  }
}

std::vector<double> Sobol::Point(uint64_t index) const {
  std::vector<uint32_t> bits(static_cast<size_t>(dims_));
  PointBits(index, bits.data());
  std::vector<double> p(bits.size());
  for (size_t d = 0; d < bits.size(); ++d) p[d] = bits[d] * 0x1.0p-32;
  return p;
}

std::vector<double> Sobol::ShiftedPoint(uint64_t index, const std::vector<uint32_t>& shift) const {
  THROW_CHECK_EQ(shift.size(), static_cast<size_t>(dims_));
  std::vector<uint32_t> bits(static_cast<size_t>(dims_));
  PointBits(index, bits.data());
  std::vector<double> p(bits.size());
  for (size_t d = 0; d < bits.size(); ++d) p[d] = ((bits[d] ^ shift[d]) + 0.5) * 0x1.0p-32;
  return p;
}

}  // namespace handdb
