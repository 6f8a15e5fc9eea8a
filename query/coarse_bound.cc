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

// ceil(sqrt(gx^2 + gy^2) / 8) for gaps gx, gy in [0, 128] PointQ units: a distance rounded up to
// 1/2 px (exact: integer squares compared, no float).
struct DiagonalGaps {
  uint8_t value[CoarseGrid::kCellUnits + 1][CoarseGrid::kCellUnits + 1];
  DiagonalGaps() {
    for (int gx = 0; gx <= CoarseGrid::kCellUnits; ++gx) {
      for (int gy = 0; gy <= CoarseGrid::kCellUnits; ++gy) {
        int u = 0;
        while (64 * u * u < gx * gx + gy * gy) ++u;  // (8u)^2 >= gx^2 + gy^2
        value[gx][gy] = static_cast<uint8_t>(u);
      }
    }
  }
};
const DiagonalGaps& Diagonals() {
  static const DiagonalGaps table;
  return table;
}

// ceil(g / 8): a gap along one axis rounded up to 1/2 px.
int AxisGap(int g) { return (g + 7) >> 3; }

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

void NeighbourGaps(PointQ q, uint8_t out[8]) {
  constexpr int kCell = CoarseGrid::kCellUnits;
  const int fx = (static_cast<int>(q.x) + CoarseGrid::kHalfUnits) & (kCell - 1);
  const int fy = (static_cast<int>(q.y) + CoarseGrid::kHalfUnits) & (kCell - 1);
  const auto& d = Diagonals().value;
  out[0] = d[fx][fy];
  out[1] = static_cast<uint8_t>(AxisGap(fy));
  out[2] = d[kCell - fx][fy];
  out[3] = static_cast<uint8_t>(AxisGap(fx));
  out[4] = static_cast<uint8_t>(AxisGap(kCell - fx));
  out[5] = d[fx][kCell - fy];
  out[6] = static_cast<uint8_t>(AxisGap(kCell - fy));
  out[7] = d[kCell - fx][kCell - fy];
}

void CoarseFields::NeighbourValuesAtBorder(size_t v, int cell, uint8_t out[9]) const {
  constexpr int kSide = CoarseGrid::kSide;
  THROW_CHECK(cell >= 0 && cell < CoarseGrid::kCells);
  const uint8_t* f = planes_.data() + (v / kBlock) * CoarseGrid::kCells * kBlock + v % kBlock;
  const int ix = cell % kSide;
  const int iy = cell / kSide;
  int k = 0;
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) {
      if (dx == 0 && dy == 0) continue;
      const int x = ix + dx;
      const int y = iy + dy;
      out[k++] = x < 0 || y < 0 || x >= kSide || y >= kSide
                     ? 0
                     : f[static_cast<size_t>(y * kSide + x) * kBlock];
    }
  }
  out[8] = f[static_cast<size_t>(cell) * kBlock];
}

int CoarseFields::PointLowerBound(size_t v, PointQ q) const {
  const int cell = CoarseGrid::CellOf(q);
  if (cell < 0) return 0;
  uint8_t values[9];
  uint8_t gaps[8];
  NeighbourValues(v, cell, values);
  NeighbourGaps(q, gaps);
  int best = values[8];
  for (int k = 0; k < 8; ++k) best = std::max(best, values[k] - gaps[k]);
  return best;
}

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
