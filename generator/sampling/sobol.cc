#include "generator/sampling/sobol.h"

#include <boost/random/sobol.hpp>

#include "base/status.h"

namespace handdb {

struct Sobol::Engine
    : boost::random::sobol_engine<uint32_t, Sobol::kBits, boost::random::default_sobol_table> {
  using sobol_engine::sobol_engine;
};

Sobol::Sobol(int dims) : dims_(dims) {
  THROW_CHECK_MSG(dims >= 1 && dims <= kMaxDims,
                  "Sobol dims " << dims << " not in 1.." << kMaxDims);
  engine_ = std::make_unique<const Engine>(static_cast<size_t>(dims));
}

Sobol::~Sobol() = default;

void Sobol::PointBits(uint64_t index, uint32_t* out) const {
  THROW_CHECK_MSG(index < (uint64_t{1} << kBits), "Sobol index " << index << " beyond 2^32");
  // Boost's sequence starts at the reference sequence's point 1 (it skips the origin).
  if (index == 0) {
    for (int d = 0; d < dims_; ++d) out[d] = 0;
    return;
  }
  Engine engine = *engine_;
  engine.seed(index - 1);
  for (int d = 0; d < dims_; ++d) out[d] = engine();
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
