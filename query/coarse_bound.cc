#include "query/coarse_bound.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "base/status.h"
#include "base/thread_pool.h"
#include "query/database.h"
#include "query/distance_transform.h"
#include "query/simd.h"

namespace handdb {

void CellHistogram::Build(std::span<const PointQ> points, FieldKind kind) {
  std::vector<uint32_t> count(CoarseGrid::kCells, 0);
  for (const PointQ& p : points) {
    const int c = CoarseGrid::CellOf(p);
    if (c >= 0) ++count[static_cast<size_t>(c)];
  }
  cells_.clear();
  counts_.clear();
  std::vector<uint32_t> first(CoarseGrid::kCells, 0);  // each cell's first entry
  for (int c = 0; c < CoarseGrid::kCells; ++c) {
    first[static_cast<size_t>(c)] = static_cast<uint32_t>(cells_.size());
    for (uint32_t left = count[static_cast<size_t>(c)]; left > 0;) {
      const uint32_t n = std::min(left, kMaxCount);
      cells_.push_back(static_cast<uint16_t>(c));
      counts_.push_back(static_cast<uint16_t>(n));
      left -= n;
    }
  }
  // The gap sums per entry: a cell's points fill its entries in order, kMaxCount each.
  std::vector<uint32_t> gap_sums(9 * cells_.size(), 0);
  std::vector<uint32_t> seen(CoarseGrid::kCells, 0);
  for (const PointQ& p : points) {
    const int c = CoarseGrid::CellOf(p);
    if (c < 0) continue;
    const size_t entry = first[static_cast<size_t>(c)] + seen[static_cast<size_t>(c)]++ / kMaxCount;
    uint8_t g[9];
    FieldGaps(kind, p, g);
    for (int k = 0; k < 9; ++k) gap_sums[9 * entry + static_cast<size_t>(k)] += g[k];
  }
  gaps_.assign(8 * cells_.size(), kNoNeighbour);
  own_gaps_.resize(cells_.size());
  constexpr int kSide = CoarseGrid::kSide;
  for (size_t i = 0; i < cells_.size(); ++i) {
    // ceil(sum / n): at most the largest gap, 34 units.
    own_gaps_[i] = static_cast<uint8_t>((gap_sums[9 * i + 8] + counts_[i] - 1) / counts_[i]);
    const int ix = cells_[i] % kSide;
    const int iy = cells_[i] / kSide;
    if (ix == 0 || iy == 0 || ix == kSide - 1 || iy == kSide - 1) continue;
    for (size_t k = 0; k < 8; ++k) {
      gaps_[8 * i + k] = static_cast<uint8_t>((gap_sums[9 * i + k] + counts_[i] - 1) / counts_[i]);
    }
  }
}

CoarseFields::CoarseFields(const Database& db, int num_threads, FieldKind kind, ThreadPool* pool)
    : kind_(kind), num_views_(db.num_views()) {
  planes_.assign(num_blocks() * CoarseGrid::kCells * kBlock, 0);
  std::vector<size_t> computed(num_blocks(), 0);
  auto fill_block = [&](size_t b, int) {
    std::vector<uint8_t> scratch(CoarseGrid::kCells);
    std::vector<uint8_t> decoded(CoarseGrid::kCells);
    std::vector<PointQ> points;  // a coded view's, decoded (not kept: every view passes here)
    uint8_t* plane = planes_.data() + b * CoarseGrid::kCells * kBlock;
    for (size_t i = 0; i < kBlock && b * kBlock + i < num_views_; ++i) {
      const auto v = static_cast<view_id_t>(b * kBlock + i);
      const uint8_t* field =
          kind == FieldKind::kBox ? db.ViewCoarseField(v, decoded.data()) : nullptr;
      if (kind == FieldKind::kCentre) {
        ComputeCentreField(db.ViewPoints(v, &points), scratch.data());
        field = scratch.data();
        ++computed[b];
      } else if (field == nullptr) {  // a shard without the section (v1.0): computed here
        ComputeCoarseField(db.ViewPoints(v, &points), scratch.data());
        field = scratch.data();
        ++computed[b];
      }
      for (int c = 0; c < CoarseGrid::kCells; ++c) {
        plane[static_cast<size_t>(c) * kBlock + i] = field[c];
      }
    }
    return true;
  };
  ParallelFor(num_blocks(), ResolveNumThreads(num_threads), fill_block, pool);
  for (size_t n : computed) computed_views_ += n;
  db.ReleaseCoarseFieldPages();
}

// The shards store box fields: kind_ stays FieldKind::kBox.
CoarseFields CoarseFields::RowMajor(const Database& db) {
  THROW_CHECK(db.has_coarse_fields());
  CoarseFields fields;
  fields.num_views_ = db.num_views();
  fields.rows_ = &db;
  return fields;
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

// Row offsets (in cells) of the eight neighbours, in NeighbourGaps' order.
constexpr ptrdiff_t kNeighbourOffsets[8] = {-CoarseGrid::kSide - 1,
                                            -CoarseGrid::kSide,
                                            -CoarseGrid::kSide + 1,
                                            -1,
                                            1,
                                            CoarseGrid::kSide - 1,
                                            CoarseGrid::kSide,
                                            CoarseGrid::kSide + 1};

#ifdef HANDDB_HAVE_AVX2_PATH
// Entry i's term for 32 views of a block: max(F(c), F(n_k) -sat g_ik) per view, bytes.
template <bool kNeighbours>
__attribute__((target("avx2"))) inline __m256i EntryValues(const uint8_t* plane,
                                                           const CellHistogram& h,
                                                           size_t i,
                                                           size_t j) {
  constexpr auto kBlock = static_cast<ptrdiff_t>(CoarseFields::kBlock);
  const uint8_t* row = plane + static_cast<size_t>(h.cells()[i]) * CoarseFields::kBlock + j;
  __m256i best = _mm256_subs_epu8(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(row)),
                                  _mm256_set1_epi8(static_cast<char>(h.own_gap(i))));
  if (!kNeighbours || !h.interior(i)) return best;
  const uint8_t* g = h.gaps(i);
  for (int k = 0; k < 8; ++k) {
    const __m256i n =
        _mm256_loadu_si256(reinterpret_cast<const __m256i*>(row + kNeighbourOffsets[k] * kBlock));
    best = _mm256_max_epu8(best, _mm256_subs_epu8(n, _mm256_set1_epi8(static_cast<char>(g[k]))));
  }
  return best;
}

// Adds count_a * a + count_b * b for 16 views (bytes of a and b) into lo (views 0-7), hi (8-15):
// the bytes interleaved per view and multiplied with one madd (int16 x int16 -> int32, counts <=
// 128 and values <= 255).
__attribute__((target("avx2"))) inline void AddWeighted(
    __m128i a, __m128i b, __m256i counts, __m256i* lo, __m256i* hi) {
  *lo = _mm256_add_epi32(*lo,
                         _mm256_madd_epi16(_mm256_cvtepu8_epi16(_mm_unpacklo_epi8(a, b)), counts));
  *hi = _mm256_add_epi32(*hi,
                         _mm256_madd_epi16(_mm256_cvtepu8_epi16(_mm_unpackhi_epi8(a, b)), counts));
}

// out[l] = sum_i count_i * byte l of entries.Values(i), for the 32 lanes l, over `n` entries:
// two entries per madd.
template <typename Entries>
__attribute__((target("avx2"))) inline void WeightedSums32(const Entries& entries,
                                                           size_t n,
                                                           uint32_t* out) {
  __m256i acc[4] = {_mm256_setzero_si256(),
                    _mm256_setzero_si256(),
                    _mm256_setzero_si256(),
                    _mm256_setzero_si256()};
  for (size_t i = 0; i < n; i += 2) {
    const bool pair = i + 1 < n;
    const __m256i a = entries.Values(i);
    const __m256i b = pair ? entries.Values(i + 1) : _mm256_setzero_si256();
    const __m256i counts =
        _mm256_set1_epi32(static_cast<int>(entries.Count(i)) |
                          (pair ? static_cast<int>(entries.Count(i + 1)) << 16 : 0));
    AddWeighted(_mm256_castsi256_si128(a), _mm256_castsi256_si128(b), counts, &acc[0], &acc[1]);
    AddWeighted(
        _mm256_extracti128_si256(a, 1), _mm256_extracti128_si256(b, 1), counts, &acc[2], &acc[3]);
  }
  for (int q = 0; q < 4; ++q) {
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out + 8 * static_cast<size_t>(q)), acc[q]);
  }
}

// L_A's entries for 32 views (from view j of the block).
template <bool kNeighbours>
struct BlockEntries {
  const uint8_t* plane;
  const CellHistogram& h;
  size_t j;
  __attribute__((target("avx2"))) __m256i Values(size_t i) const {
    return EntryValues<kNeighbours>(plane, h, i, j);
  }
  uint32_t Count(size_t i) const { return h.counts()[i]; }
};

// 32 views per step (the steps whose bit is set in `groups`).
template <bool kNeighbours>
__attribute__((target("avx2"))) void BlockSumsAvx2(const uint8_t* plane,
                                                   const CellHistogram& h,
                                                   unsigned groups,
                                                   uint32_t* out) {
  for (size_t j = 0; j < CoarseFields::kBlock; j += 32) {
    if ((groups >> (j / 32) & 1) == 0) continue;
    WeightedSums32(BlockEntries<kNeighbours>{plane, h, j}, h.num_cells(), out + j);
  }
}

// L_Bc's entries (a view's cells and counts) for 32 slots (from slot j).
struct ViewEntries {
  const uint16_t* cells;
  const uint8_t* counts;
  const SlotFields& fields;
  size_t j;
  __attribute__((target("avx2"))) __m256i Values(size_t i) const {
    return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(fields.row(cells[i]) + j));
  }
  uint32_t Count(size_t i) const { return counts[i]; }
};

// ViewHistograms::Sums: 32 slots per step.
__attribute__((target("avx2"))) void ViewSumsAvx2(const uint16_t* cells,
                                                  const uint8_t* counts,
                                                  size_t num_entries,
                                                  const SlotFields& fields,
                                                  uint32_t* out) {
  for (size_t j = 0; j < fields.stride(); j += 32) {
    WeightedSums32(ViewEntries{cells, counts, fields, j}, num_entries, out + j);
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

namespace {

// ceil(sqrt(dx^2 + dy^2) / 8) for |dx|, |dy| <= 192 PointQ units (a point of a cell to the centre
// of a neighbour is at most 1.5 cells away along each axis): a distance rounded up to 1/2 px.
struct CentreGapTable {
  static constexpr int kMax = 3 * CoarseGrid::kCellUnits / 2;
  uint8_t value[kMax + 1][kMax + 1];
  CentreGapTable() {
    for (int dx = 0; dx <= kMax; ++dx) {
      for (int dy = 0; dy <= kMax; ++dy) {
        int u = 0;
        while (64 * u * u < dx * dx + dy * dy) ++u;  // (8u)^2 >= dx^2 + dy^2
        value[dx][dy] = static_cast<uint8_t>(u);
      }
    }
  }
};

}  // namespace

void FieldGaps(FieldKind kind, PointQ q, uint8_t out[9]) {
  if (kind == FieldKind::kBox) {
    NeighbourGaps(q, out);
    out[8] = 0;
    return;
  }
  static const CentreGapTable table;
  constexpr int kCell = CoarseGrid::kCellUnits;
  // q's offset from its own cell's centre, in [-64, 63] along each axis.
  const int dx = ((static_cast<int>(q.x) + CoarseGrid::kHalfUnits) & (kCell - 1)) - kCentreOffset;
  const int dy = ((static_cast<int>(q.y) + CoarseGrid::kHalfUnits) & (kCell - 1)) - kCentreOffset;
  int k = 0;
  for (int oy = -1; oy <= 1; ++oy) {
    for (int ox = -1; ox <= 1; ++ox) {
      const uint8_t gap = table.value[std::abs(dx - ox * kCell)][std::abs(dy - oy * kCell)];
      if (ox == 0 && oy == 0) {
        out[8] = gap;
      } else {
        out[k++] = gap;
      }
    }
  }
}

void CoarseFields::NeighbourValuesAtBorder(size_t v, int cell, uint8_t out[9]) const {
  constexpr int kSide = CoarseGrid::kSide;
  THROW_CHECK(cell >= 0 && cell < CoarseGrid::kCells);
  const uint8_t* f = At(v, 0);
  const auto col = static_cast<size_t>(ColumnStride());
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
                     : f[static_cast<size_t>(y * kSide + x) * col];
    }
  }
  out[8] = f[static_cast<size_t>(cell) * col];
}

int CoarseFields::PointLowerBound(size_t v, PointQ q) const {
  const int cell = CoarseGrid::CellOf(q);
  if (cell < 0) return 0;
  uint8_t values[9];
  uint8_t gaps[9];
  NeighbourValues(v, cell, values);
  FieldGaps(kind_, q, gaps);
  int best = 0;
  for (int k = 0; k < 9; ++k) best = std::max(best, values[k] - gaps[k]);
  return best;
}

uint64_t CoarseFields::PairSum(const CellHistogram& histogram, size_t v) const {
  uint64_t sum = 0;
  for (size_t i = 0; i < histogram.num_cells(); ++i) {
    uint8_t values[9];
    NeighbourValues(v, histogram.cells()[i], values);
    int best = std::max(0, values[8] - histogram.own_gap(i));
    if (histogram.interior(i)) {
      for (int k = 0; k < 8; ++k) best = std::max(best, values[k] - histogram.gaps(i)[k]);
    }
    sum += static_cast<uint64_t>(histogram.counts()[i]) * static_cast<uint64_t>(best);
  }
  return sum;
}

void CoarseFields::BlockSums(const CellHistogram& histogram,
                             size_t block,
                             uint32_t* out,
                             bool neighbours,
                             unsigned groups) const {
  THROW_CHECK_LT(block, num_blocks());
  THROW_CHECK(rows_ == nullptr);  // the streaming products need the cell-major copy
  const uint8_t* plane = planes_.data() + block * CoarseGrid::kCells * kBlock;
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveAvx2()) {
    if (neighbours) {
      BlockSumsAvx2<true>(plane, histogram, groups, out);
    } else {
      BlockSumsAvx2<false>(plane, histogram, groups, out);
    }
    return;
  }
#endif
  for (size_t j = 0; j < kBlock; ++j) {
    if ((groups >> (j / 32) & 1) != 0) out[j] = 0;
  }
  for (size_t i = 0; i < histogram.num_cells(); ++i) {
    const uint8_t* row = plane + static_cast<size_t>(histogram.cells()[i]) * kBlock;
    const uint8_t* g = histogram.gaps(i);
    for (size_t j = 0; j < kBlock; ++j) {
      if ((groups >> (j / 32) & 1) == 0) continue;
      int best = std::max(0, row[j] - histogram.own_gap(i));
      if (neighbours && histogram.interior(i)) {
        for (int k = 0; k < 8; ++k) {
          best = std::max(best,
                          row[kNeighbourOffsets[k] * static_cast<ptrdiff_t>(kBlock) +
                              static_cast<ptrdiff_t>(j)] -
                              g[k]);
        }
      }
      out[j] += static_cast<uint32_t>(histogram.counts()[i]) * static_cast<uint32_t>(best);
    }
  }
}

void SlotFields::Reset(size_t num_slots) {
  num_slots_ = num_slots;
  stride_ = (num_slots + 31) / 32 * 32;
  values_.assign(static_cast<size_t>(CoarseGrid::kCells) * stride_, 0);
}

void SlotFields::Compute(size_t s, std::span<const PointQ> rolled) {
  THROW_CHECK_LT(s, num_slots_);
  std::array<uint8_t, CoarseGrid::kCells> field;
  ComputeCoarseField(rolled, field.data());
  for (int c = 0; c < CoarseGrid::kCells; ++c) {
    values_[static_cast<size_t>(c) * stride_ + s] = field[static_cast<size_t>(c)];
  }
}

template <typename From>
void SlotFields::CopyMapped(size_t base, size_t s, double gap_px, From from) {
  THROW_CHECK_LT(base, num_slots_);
  THROW_CHECK_LT(s, num_slots_);
  constexpr int kSide = CoarseGrid::kSide;
  // ceil(2 gap): the gap in 1/2 px rounded up (a gap beyond the byte range zeroes every value).
  const double units = std::ceil(gap_px * CoarseGrid::kValueUnitsPerPx);
  const int minus = units > 255 ? 255 : static_cast<int>(units);
  for (int iy = 0; iy < kSide; ++iy) {
    for (int ix = 0; ix < kSide; ++ix) {
      const int value = values_[static_cast<size_t>(from(ix, iy)) * stride_ + base] - minus;
      values_[static_cast<size_t>(iy * kSide + ix) * stride_ + s] =
          static_cast<uint8_t>(std::max(value, 0));
    }
  }
}

void SlotFields::CopyFlipped(size_t base, size_t s, GridFlip flip, double gap_px) {
  constexpr int kSide = CoarseGrid::kSide;
  const bool fx = flip == GridFlip::kX || flip == GridFlip::kXY;
  const bool fy = flip == GridFlip::kY || flip == GridFlip::kXY;
  CopyMapped(base, s, gap_px, [fx, fy](int ix, int iy) {
    return (fy ? kSide - 1 - iy : iy) * kSide + (fx ? kSide - 1 - ix : ix);
  });
}

void SlotFields::CopyQuarterTurned(size_t base, size_t s, double gap_px) {
  constexpr int kSide = CoarseGrid::kSide;
  CopyMapped(base, s, gap_px, [](int ix, int iy) { return ix * kSide + (kSide - 1 - iy); });
}

ViewHistograms::ViewHistograms(const Database& db, int num_threads, ThreadPool* pool) {
  const size_t num_views = db.num_views();
  // Per view its entries, built in parallel into per-chunk lists, then concatenated.
  constexpr size_t kChunk = 1024;
  const size_t num_chunks = (num_views + kChunk - 1) / kChunk;
  std::vector<std::vector<uint16_t>> chunk_cells(num_chunks);
  std::vector<std::vector<uint8_t>> chunk_counts(num_chunks);
  std::vector<std::vector<uint32_t>> chunk_sizes(num_chunks);
  auto histograms = [&](size_t k, int) {
    // Plain arrays and local pointers: the byte stores below may alias anything, so members of
    // vectors would be reloaded after each one.
    std::array<uint32_t, CoarseGrid::kCells + 1> count{};
    std::vector<uint16_t> ids;
    std::vector<uint16_t> entry_cells;
    std::vector<uint32_t> entry_counts;
    std::vector<PointQ> decoded;  // a coded view's points (not kept)
    std::vector<uint16_t> cells;
    std::vector<uint8_t> counts;
    std::vector<uint32_t> sizes;
    for (size_t v = k * kChunk; v < std::min(num_views, (k + 1) * kChunk); ++v) {
      // Every point's cell (an off-grid point goes to a spare counter), then the counts, then
      // the cells in the order first met (the sums do not care about the order).
      const std::span<const PointQ> pts = db.ViewPoints(static_cast<view_id_t>(v), &decoded);
      ids.resize(pts.size());
      uint16_t* id = ids.data();
      uint32_t* cnt = count.data();
      for (size_t i = 0; i < pts.size(); ++i) {
        const int c = CoarseGrid::CellOf(pts[i]);
        id[i] = static_cast<uint16_t>(c < 0 ? CoarseGrid::kCells : c);
      }
      for (size_t i = 0; i < pts.size(); ++i) ++cnt[id[i]];
      cnt[CoarseGrid::kCells] = 0;
      // Each cell once, where it is first met (its count is then cleared), without a branch:
      // every point writes a slot and advances only if its cell was not yet written.
      entry_cells.resize(pts.size() + 1);
      entry_counts.resize(pts.size() + 1);
      size_t m = 0;
      for (size_t i = 0; i < pts.size(); ++i) {
        const uint16_t c = id[i];
        entry_cells[m] = c;
        entry_counts[m] = cnt[c];
        m += cnt[c] != 0;
        cnt[c] = 0;
      }
      const size_t before = cells.size();
      for (size_t e = 0; e < m; ++e) {
        for (uint32_t left = entry_counts[e]; left > 0;) {  // a cell over kMaxCount: split
          const uint32_t n = std::min(left, kMaxCount);
          cells.push_back(entry_cells[e]);
          counts.push_back(static_cast<uint8_t>(n));
          left -= n;
        }
      }
      sizes.push_back(static_cast<uint32_t>(cells.size() - before));
    }
    chunk_cells[k] = std::move(cells);
    chunk_counts[k] = std::move(counts);
    chunk_sizes[k] = std::move(sizes);
    return true;
  };
  ParallelFor(num_chunks, ResolveNumThreads(num_threads), histograms, pool);
  begin_.assign(num_views + 1, 0);
  // Reserved whole, so the concatenation moves each entry once (no regrowth: fewer pages touched).
  size_t total = 0;
  for (const std::vector<uint16_t>& c : chunk_cells) total += c.size();
  cells_.reserve(total);
  counts_.reserve(total);
  size_t v = 0;
  for (size_t k = 0; k < num_chunks; ++k) {
    for (uint32_t n : chunk_sizes[k]) {
      begin_[v + 1] = begin_[v] + n;
      ++v;
    }
    cells_.insert(cells_.end(), chunk_cells[k].begin(), chunk_cells[k].end());
    counts_.insert(counts_.end(), chunk_counts[k].begin(), chunk_counts[k].end());
    std::vector<uint16_t>().swap(chunk_cells[k]);
    std::vector<uint8_t>().swap(chunk_counts[k]);
  }
}

void ViewHistograms::Sums(size_t v, const SlotFields& fields, uint32_t* out) const {
  THROW_CHECK_LT(v, num_views());
  const uint16_t* cells = cells_.data() + begin_[v];
  const uint8_t* counts = counts_.data() + begin_[v];
  const size_t n = num_entries(v);
#ifdef HANDDB_HAVE_AVX2_PATH
  if (HaveAvx2()) {
    ViewSumsAvx2(cells, counts, n, fields, out);
    return;
  }
#endif
  std::fill(out, out + fields.stride(), 0u);
  for (size_t i = 0; i < n; ++i) {
    const uint8_t* row = fields.row(cells[i]);
    for (size_t j = 0; j < fields.stride(); ++j) {
      out[j] += static_cast<uint32_t>(counts[i]) * row[j];
    }
  }
}

}  // namespace handdb
