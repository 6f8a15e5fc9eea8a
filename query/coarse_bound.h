// The search's cheap exact lower bound of the query -> view term A, before any kd-tree
// (the proof in docs/query.md "The coarse B bound").
//
// The first bound (query/distance_transform.h) is on the view -> query term B. For the rolled
// query Q_r with n_r(c) points in coarse cell c (format/coarse_field.h; points off the grid
// count 0, always valid):
//
//   A(v, r) = mean_q d(q, Y_v) >= sum_c n_r(c) F_v(c) / |Q_r|  =: L_A(v, r)
//
// valid for every roll. A hand's ~600 points occupy ~150-250 of the 1,849 cells, so per pair it
// is a short dot product; per rolled query and every view at once it is a matrix-vector product,
// which CoarseFields computes from a cell-major copy of the fields (views side by side, so one
// cell's values for 32 views are one 32-byte load) instead of one gather per cell and pair. The
// search uses a tighter form that also reads each cell's eight neighbours (CoarseFields::PairSum;
// docs/query.md, "Neighbour terms in L_A").
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "base/huge_pages.h"
#include "format/coarse_field.h"
#include "format/view.h"
#include "query/database.h"

namespace handdb {

enum class GridFlip;  // query/distance_transform.h

// What a CoarseFields holds per cell of a view (format/coarse_field.h): the distance from the
// cell's closed box to the view (F_v, the shards' section), or from the cell's centre (C_v,
// computed on open for the exact search, docs/query.md). A query point q is credited, for its
// own cell and each neighbour n, the value less q's gap to n: its distance to n's box (0 for its
// own cell) or to n's centre.
enum class FieldKind : uint8_t { kBox, kCentre };

// The rolled query's occupied cells and their point counts. A cell holding more than kMaxCount
// points is listed more than once (the sum is the same), so every product count x field value
// fits 16 bits in the vector kernel. Per entry also the mean gap from its points to each of the
// eight neighbouring cells (the neighbour term of L_A, CoarseFields::BlockSums) and to its own
// cell (0 for boxes), rounded up, for the field kind given.
class CellHistogram {
 public:
  static constexpr uint32_t kMaxCount = 128;
  // An entry's gap to a neighbour that is off the grid, or that the bound does not read (cells
  // on the grid's border): larger than any field value, so the neighbour's term is 0.
  static constexpr uint8_t kNoNeighbour = 255;
  void Build(std::span<const PointQ> points, FieldKind kind = FieldKind::kBox);
  // L_A in px for a row-major field (kCells bytes): sum_c n(c) F(c) / |Q| / 2, rounded down by a
  // relative 1e-12 (so it never exceeds the exact value), given the number of query points.
  double LowerBound(const uint8_t* field, size_t num_query_points) const {
    return static_cast<double>(Sum([field](int c) { return field[c]; })) /
           CoarseGrid::kValueUnitsPerPx / static_cast<double>(num_query_points) * (1 - 1e-12);
  }
  // sum_c n(c) value(c) in field units (exact integer).
  template <typename ValueAt>
  uint64_t Sum(ValueAt value_at) const {
    uint64_t sum = 0;
    for (size_t i = 0; i < cells_.size(); ++i) {
      sum += static_cast<uint64_t>(counts_[i]) * value_at(cells_[i]);
    }
    return sum;
  }
  size_t num_cells() const { return cells_.size(); }
  std::span<const uint16_t> cells() const { return cells_; }
  std::span<const uint16_t> counts() const { return counts_; }
  // Entry i's gaps: ceil(sum_q gap(q, box_k) / n_i) in 1/2 px over its points q, for the eight
  // neighbours k in NeighbourGaps' order; kNoNeighbour for every k if the cell is on the grid's
  // border.
  const uint8_t* gaps(size_t i) const { return gaps_.data() + 8 * i; }
  bool interior(size_t i) const { return gaps_[8 * i] != kNoNeighbour; }
  // Entry i's gap to its own cell: ceil(sum_q gap(q, own) / n_i), 0 for boxes.
  uint8_t own_gap(size_t i) const { return own_gaps_[i]; }

 private:
  std::vector<uint16_t> cells_;
  std::vector<uint16_t> counts_;  // each <= kMaxCount
  std::vector<uint8_t> gaps_;     // 8 per entry
  std::vector<uint8_t> own_gaps_;
};

// The gaps (rounded up to 1/2 px) from a point q on the coarse grid to the boxes of its cell's
// eight neighbours, in the order (-1,-1), (0,-1), (1,-1), (-1,0), (1,0), (-1,1), (0,1), (1,1).
void NeighbourGaps(PointQ q, uint8_t out[8]);

// The gaps for a field kind: out[0..7] to the eight neighbours (NeighbourGaps' order), out[8]
// to q's own cell. Boxes: NeighbourGaps and 0. Centres: |q - centre(n)| rounded up to 1/2 px,
// the smallest u with (8u)^2 >= dx^2 + dy^2 (exact integers).
void FieldGaps(FieldKind kind, PointQ q, uint8_t out[9]);

// Every view's coarse field, cell-major in blocks of kBlock views. Box fields (kBox): the shard's
// own (format v1.1) where the shard has the section, else computed from the points, in parallel
// (~110 us per view); the copy replaces the shards' row-major sections in memory (their mapped
// pages are released once copied), so the fields are resident once. Centre fields (kCentre, what
// the exact search uses since they bound A tighter): computed from the points (~60 us per view),
// the shards' sections never read. Or (RowMajor) the shards' box sections themselves, read in
// place, for searches that read a few views' fields.
class CoarseFields {
 public:
  static constexpr size_t kBlock = 128;  // views per block

  CoarseFields() = default;
  // kBox: the shards' F_v (computed where a shard lacks the section); kCentre: C_v, computed
  // from every view's points (~60 us per view, in parallel: num_threads, on `pool` when given).
  CoarseFields(const Database& db,
               int num_threads,
               FieldKind kind = FieldKind::kBox,
               ThreadPool* pool = nullptr);
  // The shards' own row-major fields, read in place (nothing copied, nothing computed): for
  // searches that read the fields of a few views only (indexed search), where the cell-major
  // copy of every view would cost more than the search (~4 s and 1.2 GB at 10M virtual views).
  // Needs db.has_coarse_fields(); BlockSums is not available.
  static CoarseFields RowMajor(const Database& db);
  bool empty() const { return num_views_ == 0; }
  FieldKind kind() const { return kind_; }
  size_t num_views() const { return num_views_; }
  size_t num_blocks() const { return (num_views_ + kBlock - 1) / kBlock; }
  size_t computed_views() const { return computed_views_; }  // 0: all read from the shards
  // F_v(cell) (or C_v(cell)) in 1/2 px.
  uint8_t value(size_t v, int cell) const { return At(v, cell)[0]; }
  // L_A's sum for view v and the query of `histogram` (built for this kind; 1/2 px units, exact
  // integer): over the histogram's entries i (cell c, n_i points, mean gaps g_ik, own gap g_i),
  //   n_i * max(F_v(c) - g_i, max_k F_v(n_k) - g_ik)
  // (a negative term counts 0; border cells use their own cell alone; boxes have g_i = 0). It
  // is <= the sum of the entry's points' PointLowerBound, hence <= the sum of their distances to
  // Y_v (docs/query.md): each point's bound is >= F_v(n) - its gap to n for its own cell and
  // each neighbour n, and summed over the entry's points that is n_i F_v(n) - sum of gaps >= n_i
  // (F_v(n) - g). It is >= sum_c n(c) (F_v(c) - g_i), the cell-only bound.
  uint64_t PairSum(const CellHistogram& histogram, size_t v) const;
  // PairSum for the views of block b: out[i] for view b kBlock + i, i < kBlock (views past the
  // end get 0). With `neighbours` false the cell-only sum sum_i n_i (F_v(c) - g_i) (<= PairSum,
  // ~1/4 of the work); only the groups of 32 views whose bit is set in `groups` (bit g: views
  // 32g..32g+31 of the block) are written.
  void BlockSums(const CellHistogram& histogram,
                 size_t block,
                 uint32_t* out,
                 bool neighbours = true,
                 unsigned groups = 0xF) const;
  // A lower bound of d(q, Y_v) in 1/2 px from q's cell c and its eight neighbours n:
  //   max_n F_v(n) - gap(q, n)   (boxes: the box's point p nearest q, gap 0 for n = c;
  //                               centres: p = centre(n))
  // since d(q, Y) >= d(p, Y) - |q - p| >= F_v(n) - |q - p|. The gaps are rounded up to 1/2 px
  // (FieldGaps), so the integer result never exceeds the true bound; neighbours off the grid and
  // negative terms count 0. 0 for q off the grid. The linear scans of A
  // start from it, so a pair is often dropped before any point is scanned (docs/query.md). The
  // search computes it in bulk (NeighbourValues once per cell, then one byte-wise max per
  // point); this is the plain form, for tests.
  int PointLowerBound(size_t v, PointQ q) const;
  // F_v of cell c (out[8]) and of its eight neighbours (out[0..7], in NeighbourGaps' order; 0
  // for a neighbour off the grid).
  void NeighbourValues(size_t v, int cell, uint8_t out[9]) const {
    constexpr int kSide = CoarseGrid::kSide;
    const int ix = cell % kSide;
    const int iy = cell / kSide;
    if (ix == 0 || iy == 0 || ix == kSide - 1 || iy == kSide - 1) {
      NeighbourValuesAtBorder(v, cell, out);
      return;
    }
    const uint8_t* f = At(v, cell);
    const ptrdiff_t col = ColumnStride();
    const ptrdiff_t row = kSide * col;
    out[0] = f[-row - col];
    out[1] = f[-row];
    out[2] = f[-row + col];
    out[3] = f[-col];
    out[4] = f[col];
    out[5] = f[row - col];
    out[6] = f[row];
    out[7] = f[row + col];
    out[8] = f[0];
  }

  // Hints the cache lines NeighbourValues(v, cell) reads (interior cells only).
  void PrefetchNeighbours(size_t v, int cell) const {
    constexpr int kSide = CoarseGrid::kSide;
    const int ix = cell % kSide;
    const int iy = cell / kSide;
    if (ix == 0 || iy == 0 || ix == kSide - 1 || iy == kSide - 1) return;
    const uint8_t* f = At(v, cell);
    const ptrdiff_t col = ColumnStride();
    const ptrdiff_t row = kSide * col;
    for (ptrdiff_t r : {-row, ptrdiff_t{0}, row}) {
      for (ptrdiff_t c : {-col, ptrdiff_t{0}, col}) __builtin_prefetch(f + r + c);
    }
  }

 private:
  void NeighbourValuesAtBorder(size_t v, int cell, uint8_t out[9]) const;
  // Where F_v(cell) is, and how far apart two horizontally adjacent cells of one view are.
  const uint8_t* At(size_t v, int cell) const {
    if (rows_ != nullptr) {
      return rows_->SearchCoarseField(static_cast<view_id_t>(v)) + static_cast<size_t>(cell);
    }
    return planes_.data() +
           ((v / kBlock) * CoarseGrid::kCells + static_cast<size_t>(cell)) * kBlock + v % kBlock;
  }
  ptrdiff_t ColumnStride() const { return rows_ != nullptr ? 1 : static_cast<ptrdiff_t>(kBlock); }
  const Database* rows_ = nullptr;  // RowMajor: the database whose shards hold the fields
  FieldKind kind_ = FieldKind::kBox;
  size_t num_views_ = 0;
  size_t computed_views_ = 0;
  // [block][cell][view in block], in huge pages: written once, first touched in one go.
  std::vector<uint8_t, HugePageAllocator<uint8_t>> planes_;
};

// The coarse bound of the view -> query term B (docs/query.md, "The coarse B bound"). For slot
// s's rolled query Q_s, G_s(c) is Q_s's coarse field (format/coarse_field.h: the distance from
// the closed box of cell c to Q_s, rounded down to 1/2 px); every view point y in c lies in the
// box, so d(y, Q_s) >= G_s(c) and
//
//   B(v, s) = mean_y d(y, Q_s) >= sum_c n_v(c) G_s(c) / |Y_v|  =: L_Bc(v, s)
//
// with n_v(c) the view's points in c (points off the grid count 0). SlotFields holds every
// slot's G_s cell-major (one cell's values for 32 slots are one 32-byte load), ViewHistograms
// every view's cells and counts, so L_Bc of one view for all slots is ~150 short vector madds.
class SlotFields {
 public:
  // Room for `num_slots` slots, all values 0 (a valid bound) until set.
  void Reset(size_t num_slots);
  size_t num_slots() const { return num_slots_; }
  // Slots per cell row: num_slots rounded up to a multiple of 32.
  size_t stride() const { return stride_; }
  // Sets slot s's values from its own rolled query's points.
  void Compute(size_t s, std::span<const PointQ> rolled);
  // Sets slot s's values from slot `base`'s, for a rolled query within `gap_px` per point of
  // flip(base's): G_s(c) >= G_base(flip(c)) - gap, since flip maps the closed box of c onto the
  // closed box of flip(c) (the grid is symmetric about the origin) and d(p, Q_s) >= d(p,
  // flip(Q_base)) - gap. The gap is rounded up to 1/2 px and subtracted saturating at 0.
  void CopyFlipped(size_t base, size_t s, GridFlip flip, double gap_px);
  // The same for a rolled query within `gap_px` of T(base's) for the quarter turn T(x, y) =
  // (y, -x) (roll r + R/4 of roll r): T^-1 maps the closed box of cell (ix, iy) onto that of
  // (42 - iy, ix), so G_s(ix, iy) >= G_base(42 - iy, ix) - gap.
  void CopyQuarterTurned(size_t base, size_t s, double gap_px);
  uint8_t value(size_t s, int cell) const {
    return values_[static_cast<size_t>(cell) * stride_ + s];
  }
  const uint8_t* row(int cell) const {
    return values_.data() + static_cast<size_t>(cell) * stride_;
  }

 private:
  // values(s, cell (ix, iy)) = max(0, values(base, from(ix, iy)) - ceil(2 gap_px)).
  template <typename From>
  void CopyMapped(size_t base, size_t s, double gap_px, From from);
  size_t num_slots_ = 0;
  size_t stride_ = 0;
  std::vector<uint8_t> values_;  // [cell][slot]
};

class ViewHistograms {
 public:
  static constexpr uint32_t kMaxCount = 255;  // a fuller cell is listed more than once
  ViewHistograms() = default;
  // Every view's histogram, computed from its points in parallel (~2 us per view; num_threads,
  // on `pool` when given).
  ViewHistograms(const Database& db, int num_threads, ThreadPool* pool = nullptr);
  bool empty() const { return begin_.empty(); }
  size_t num_views() const { return begin_.empty() ? 0 : begin_.size() - 1; }
  // Bytes held: 3 per entry and 8 per view.
  size_t bytes() const { return begin_.size() * 8 + cells_.size() * 3; }
  size_t num_entries(size_t v) const { return begin_[v + 1] - begin_[v]; }
  // sum_c n_v(c) G_s(c) in 1/2 px (exact integer) for every slot: out[s] for s < fields.stride()
  // (padding slots get 0).
  void Sums(size_t v, const SlotFields& fields, uint32_t* out) const;

 private:
  std::vector<uint64_t> begin_;  // num_views + 1 entry offsets
  std::vector<uint16_t> cells_;
  std::vector<uint8_t> counts_;
};

}  // namespace handdb
