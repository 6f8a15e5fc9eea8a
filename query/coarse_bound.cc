#include "query/coarse_bound.h"

#include <algorithm>

#include "base/status.h"
#include "base/thread_pool.h"
#include "query/database.h"
#include "query/simd.h"

namespace handdb {

void CellHistogram::Build(std::span<const PointQ> points) {
  std::vector<uint32_t> count(CoarseGrid::kCells, 0);
  for (const PointQ& p : points) {
    const int c = CoarseGrid::CellOf(p);
    if (c >= 0) ++count[static_cast<size_t>(c)];
  }
  cells_.clear();
  counts_.clear();
  for (int c = 0; c < CoarseGrid::kCells; ++c) {
    for (uint32_t left = count[static_cast<size_t>(c)]; left > 0;) {
      const uint32_t n = std::min(left, kMaxCount);
      cells_.push_back(static_cast<uint16_t>(c));
      counts_.push_back(static_cast<uint16_t>(n));
      left -= n;
    }
  }
}

CoarseFields::CoarseFields(const Database& db, int num_threads) : num_views_(db.num_views()) {
  planes_.assign(num_blocks() * CoarseGrid::kCells * kBlock, 0);
  std::vector<size_t> computed(num_blocks(), 0);
  ParallelFor(num_blocks(), ResolveNumThreads(num_threads), [&](size_t b, int) {
    std::vector<uint8_t> scratch(CoarseGrid::kCells);
    uint8_t* plane = planes_.data() + b * CoarseGrid::kCells * kBlock;
    for (size_t i = 0; i < kBlock && b * kBlock + i < num_views_; ++i) {
      const auto v = static_cast<view_id_t>(b * kBlock + i);
      const uint8_t* field = db.coarse_field(v);
      if (field == nullptr) {  // a shard without the section (v1.0): computed here
        ComputeCoarseField(db.points(v), scratch.data());
        field = scratch.data();
        ++computed[b];
      }
      for (int c = 0; c < CoarseGrid::kCells; ++c) {
        plane[static_cast<size_t>(c) * kBlock + i] = field[c];
      }
    }
    return true;
  });
  for (size_t n : computed) computed_views_ += n;
  db.ReleaseCoarseFieldPages();
}

namespace {

#ifdef HANDDB_HAVE_AVX2_PATH
// Two cells at a time: their bytes interleaved per view and multiplied by their counts with one
// madd (int16 x int16 -> int32, counts <= 128 and values <= 255), 16 views per step.
__attribute__((target("avx2"))) void BlockSumsAvx2(const uint8_t* plane,
                                                   const uint16_t* cells,
                                                   const uint16_t* counts,
                                                   size_t num_cells,
                                                   uint32_t* out) {
  constexpr size_t kBlock = CoarseFields::kBlock;
  for (size_t j = 0; j < kBlock; j += 16) {
    __m256i lo = _mm256_setzero_si256();
    __m256i hi = _mm256_setzero_si256();
    size_t i = 0;
    for (; i + 2 <= num_cells; i += 2) {
      const __m128i a =
          _mm_loadu_si128(reinterpret_cast<const __m128i*>(plane + cells[i] * kBlock + j));
      const __m128i b =
          _mm_loadu_si128(reinterpret_cast<const __m128i*>(plane + cells[i + 1] * kBlock + j));
      const __m256i n =
          _mm256_set1_epi32(static_cast<int>(counts[i]) | (static_cast<int>(counts[i + 1]) << 16));
      lo =
          _mm256_add_epi32(lo, _mm256_madd_epi16(_mm256_cvtepu8_epi16(_mm_unpacklo_epi8(a, b)), n));
      hi =
          _mm256_add_epi32(hi, _mm256_madd_epi16(_mm256_cvtepu8_epi16(_mm_unpackhi_epi8(a, b)), n));
    }
    if (i < num_cells) {
      const __m128i a =
          _mm_loadu_si128(reinterpret_cast<const __m128i*>(plane + cells[i] * kBlock + j));
      const __m256i n = _mm256_set1_epi32(static_cast<int>(counts[i]));
      const __m128i zero = _mm_setzero_si128();
      lo = _mm256_add_epi32(lo,
                            _mm256_madd_epi16(_mm256_cvtepu8_epi16(_mm_unpacklo_epi8(a, zero)), n));
      hi = _mm256_add_epi32(hi,
                            _mm256_madd_epi16(_mm256_cvtepu8_epi16(_mm_unpackhi_epi8(a, zero)), n));
    }
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out + j), lo);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out + j + 8), hi);
  }
}
#endif

}  // namespace

void CoarseFields::BlockSums(const CellHistogram& histogram, size_t block, uint32_t* out) const {
  THROW_CHECK_LT(block, num_blocks());
  const uint8_t* plane = planes_.data() + block * CoarseGrid::kCells * kBlock;
  const std::span<const uint16_t> cells = histogram.cells();
  const std::span<const uint16_t> counts = histogram.counts();
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveAvx2()) {
    BlockSumsAvx2(plane, cells.data(), counts.data(), cells.size(), out);
    return;
  }
#endif
  std::fill(out, out + kBlock, 0u);
  for (size_t i = 0; i < cells.size(); ++i) {
    const uint8_t* row = plane + static_cast<size_t>(cells[i]) * kBlock;
    for (size_t j = 0; j < kBlock; ++j) out[j] += static_cast<uint32_t>(counts[i]) * row[j];
  }
}

}  // namespace handdb
