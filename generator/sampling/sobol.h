// Sobol' low-discrepancy sequence in up to 21 dimensions, with the direction numbers of Joe & Kuo
// (new-joe-kuo-6.21201, "Constructing Sobol sequences with better two-dimensional projections",
// SIAM J. Sci. Comput. 30, 2008) as shipped in Boost.Random's sobol table. Points in Gray-code
// order (Antonov-Saleev), as in the reference implementation and SciPy's unscrambled Sobol: point 0
// is the origin, point 1 is (1/2, ..., 1/2). Boost's engine starts at point 1, so point i is
// Boost's point i - 1.
// An optional digital shift (XOR of a per-dimension random word) randomises the sequence from a
// seed while keeping its net properties.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

namespace handdb {

class Sobol {
 public:
  static constexpr int kMaxDims = 21;
  static constexpr int kBits = 32;

  explicit Sobol(int dims);
  ~Sobol();
  Sobol(const Sobol&) = delete;
  Sobol& operator=(const Sobol&) = delete;
  int dims() const { return dims_; }

  // Point `index` (0-based) as 32-bit integers: coordinate = value / 2^32.
  void PointBits(uint64_t index, uint32_t* out) const;
  // Point `index` in [0, 1)^dims.
  std::vector<double> Point(uint64_t index) const;
  // Point `index` XOR `shift` (one word per dimension), mapped to the centre of its 2^-32 cell,
  // so every coordinate lies strictly inside (0, 1).
  std::vector<double> ShiftedPoint(uint64_t index, const std::vector<uint32_t>& shift) const;

 private:
  struct Engine;  // Boost's sobol_engine, kept out of this header

  int dims_;
  // At point 1; copied and seeked per point, so queries stay const and safe from many threads.
  std::unique_ptr<const Engine> engine_;
};

}  // namespace handdb
