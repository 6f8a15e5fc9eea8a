#include "format/coarse_field.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "format/shard_layout.h"

namespace handdb {
namespace {

static_assert(CoarseGrid::kCells == shard::kCoarseFieldSize);

constexpr int64_t kInf64 = std::numeric_limits<int64_t>::max();

// Distance from coordinate c to the closed interval [lo, lo + kCellUnits].
int64_t Gap(int32_t c, int32_t lo) {
  const int32_t hi = lo + CoarseGrid::kCellUnits;
  return c < lo ? lo - c : (c > hi ? c - hi : 0);
}

// floor(sqrt(d2) in 1/2 px), saturating at 255. Exact: sqrt is correctly rounded and the scale
// (2 / kPointScale = 1/8) is a power of two; no integer d2 < 2^53 has a root within rounding
// distance below a multiple of 8.
uint8_t ToUnits(int64_t d2) {
  const double units =
      std::floor(std::sqrt(static_cast<double>(d2)) * CoarseGrid::kValueUnitsPerPx / kPointScale);
  return static_cast<uint8_t>(std::min(units, 255.0));
}

}  // namespace

int64_t CoarseCellDistanceSquaredBruteForce(std::span<const PointQ> view, int ix, int iy) {
  const int32_t x0 = -CoarseGrid::kHalfUnits + ix * CoarseGrid::kCellUnits;
  const int32_t y0 = -CoarseGrid::kHalfUnits + iy * CoarseGrid::kCellUnits;
  int64_t best = kInf64;
  for (const PointQ& p : view) {
    const int64_t gx = Gap(p.x, x0);
    const int64_t gy = Gap(p.y, y0);
    best = std::min(best, gx * gx + gy * gy);
  }
  return best;
}

int64_t CentreDistanceSquaredBruteForce(std::span<const PointQ> view, int ix, int iy) {
  const int64_t cx = -CoarseGrid::kHalfUnits + ix * CoarseGrid::kCellUnits + kCentreOffset;
  const int64_t cy = -CoarseGrid::kHalfUnits + iy * CoarseGrid::kCellUnits + kCentreOffset;
  int64_t best = kInf64;
  for (const PointQ& p : view) {
    best = std::min(best, (p.x - cx) * (p.x - cx) + (p.y - cy) * (p.y - cy));
  }
  return best;
}

namespace {

// The lower envelope (Felzenszwalb & Huttenlocher) of the parabolas (a - va[i])^2 + vf[i], i < m,
// with va strictly increasing, in exact integer fractions, built in place: the envelope's
// vertices are a subsequence of the parabolas. zn / zd is the left boundary of each (zd > 0;
// index 0 is -infinity and never read). Returns the index of the last vertex.
size_t LowerEnvelope(size_t m, int64_t* va, int64_t* vf, int64_t* zn, int64_t* zd) {
  size_t k = 0;
  for (size_t q = 1; q < m; ++q) {
    const int64_t aq = va[q];
    const int64_t fq = vf[q];
    int64_t num = 0;
    int64_t den = 0;
    for (;;) {
      num = (fq + aq * aq) - (vf[k] + va[k] * va[k]);
      den = 2 * (aq - va[k]);
      // Pop while the new boundary is at or left of the top's left boundary.
      if (k > 0 && num * zd[k] <= zn[k] * den) {
        --k;
        continue;
      }
      break;
    }
    ++k;
    va[k] = aq;
    vf[k] = fq;
    zn[k] = num;
    zd[k] = den;
  }
  return k;
}

// The envelope's value at kSide + 1 points along a, a_e = first + e * kCellUnits, into d2.
void EvaluateEnvelope(size_t k,
                      const int64_t* va,
                      const int64_t* vf,
                      const int64_t* zn,
                      const int64_t* zd,
                      int64_t first,
                      int64_t* d2) {
  size_t j = 0;
  for (int e = 0; e <= CoarseGrid::kSide; ++e) {
    const int64_t a = first + static_cast<int64_t>(e) * CoarseGrid::kCellUnits;
    while (j < k && zn[j + 1] < a * zd[j + 1]) ++j;
    const int64_t da = a - va[j];
    d2[e] = da * da + vf[j];
  }
}

// Envelope scratch for up to n parabolas.
struct EnvelopeScratch {
  std::vector<int64_t> va, vf, zn, zd;
  void Reserve(size_t n) {
    va.resize(n);
    vf.resize(n);
    zn.resize(n);
    zd.resize(n);
  }
};

constexpr int kSide = CoarseGrid::kSide;
constexpr int kCell = CoarseGrid::kCellUnits;
constexpr int kHalf = CoarseGrid::kHalfUnits;

// Empty views get all zeros (a valid bound: no distance is negative).
bool ZeroIfEmpty(std::span<const PointQ> view, uint8_t* out) {
  if (!view.empty()) return false;
  std::fill(out, out + CoarseGrid::kCells, uint8_t{0});
  return true;
}

}  // namespace

void ComputeCoarseField(std::span<const PointQ> view, uint8_t* out) {
  if (ZeroIfEmpty(view, out)) return;
  // The envelope runs along one axis ("a") over bands of cells across the other ("b"), and needs
  // the points sorted by a. A database view's points come in raster order (sorted by y), so a = y
  // and bands are columns; any other set is sorted by x and bands are rows.
  thread_local std::vector<std::pair<int32_t, int32_t>> pts;  // (a, b)
  pts.clear();
  const bool by_y =
      std::is_sorted(view.begin(), view.end(), [](PointQ p, PointQ q) { return p.y < q.y; });
  for (const PointQ& p : view) pts.emplace_back(by_y ? p.y : p.x, by_y ? p.x : p.y);
  if (!by_y) std::sort(pts.begin(), pts.end());
  const size_t n = pts.size();
  thread_local EnvelopeScratch env;
  env.Reserve(n);
  int64_t edge_d2[kSide + 1];
  int64_t inside_d2[kSide];

  for (int band = 0; band < kSide; ++band) {
    const int32_t b0 = -kHalf + band * kCell;
    // The parabolas (a - p.a)^2 + gap_b(p)^2, one per distinct a (the smallest gap_b^2).
    size_t m = 0;
    std::fill(inside_d2, inside_d2 + kSide, kInf64);
    for (size_t i = 0; i < n; ++i) {
      const int64_t gb = Gap(pts[i].second, b0);
      const int64_t f = gb * gb;
      const int64_t a = pts[i].first;
      // Points inside a cell's a range: the distance to that cell is gap_b alone.
      const int64_t cell = (a + kHalf) / kCell;
      if (a >= -kHalf && cell < kSide) inside_d2[cell] = std::min(inside_d2[cell], f);
      if (m > 0 && env.va[m - 1] == a) {
        env.vf[m - 1] = std::min(env.vf[m - 1], f);
      } else {
        env.va[m] = a;
        env.vf[m] = f;
        ++m;
      }
    }
    const size_t k = LowerEnvelope(m, env.va.data(), env.vf.data(), env.zn.data(), env.zd.data());
    // Evaluate at the cell edges along a, in increasing order.
    EvaluateEnvelope(
        k, env.va.data(), env.vf.data(), env.zn.data(), env.zd.data(), -kHalf, edge_d2);
    for (int c = 0; c < kSide; ++c) {
      const uint8_t value = ToUnits(std::min({edge_d2[c], edge_d2[c + 1], inside_d2[c]}));
      // a = y: band is the column ix, c the row iy; a = x: band is the row, c the column.
      out[by_y ? static_cast<size_t>(c) * kSide + band : static_cast<size_t>(band) * kSide + c] =
          value;
    }
  }
}

void ComputeCentreField(std::span<const PointQ> view, uint8_t* out) {
  if (ZeroIfEmpty(view, out)) return;
  // The points as rows of equal y, sorted by x within a row (a database view's points come
  // sorted by y, then x). The centres of one column of cells (x = bc) see row r's points at
  // best min_p |p.x - bc| away along x, so the column's values are the lower envelope of one
  // parabola per row, (y - y_r)^2 + min_p (p.x - bc)^2, at the centres' y: per column one pass
  // over the rows (a pointer per row moves right as bc grows) instead of over every point.
  auto by_yx = [](PointQ p, PointQ q) { return p.y != q.y ? p.y < q.y : p.x < q.x; };
  std::span<const PointQ> pts = view;
  if (!std::is_sorted(view.begin(), view.end(), by_yx)) {  // sorted in a copy, else read in place
    thread_local std::vector<PointQ> sorted;
    sorted.assign(view.begin(), view.end());
    std::sort(sorted.begin(), sorted.end(), by_yx);
    pts = sorted;
  }
  thread_local std::vector<int64_t> row_y;
  thread_local std::vector<uint32_t> row_end, next;  // per row: its end, its first x >= bc
  row_y.clear();
  row_end.clear();
  next.clear();
  for (uint32_t i = 0; i < pts.size(); ++i) {
    if (row_y.empty() || row_y.back() != pts[i].y) {
      if (!row_y.empty()) row_end.push_back(i);
      row_y.push_back(pts[i].y);
      next.push_back(i);
    }
  }
  row_end.push_back(static_cast<uint32_t>(pts.size()));
  const size_t m = row_y.size();
  thread_local EnvelopeScratch env;
  env.Reserve(m);
  int64_t d2[kSide + 1];
  for (int column = 0; column < kSide; ++column) {
    const int32_t bc = -kHalf + column * kCell + kCentreOffset;
    for (size_t r = 0; r < m; ++r) {
      const uint32_t begin = r == 0 ? 0 : row_end[r - 1];
      uint32_t i = next[r];
      while (i < row_end[r] && pts[i].x < bc) ++i;
      next[r] = i;
      int64_t best = kInf64;
      if (i < row_end[r]) best = static_cast<int64_t>(pts[i].x) - bc;
      if (i > begin) best = std::min<int64_t>(best, bc - static_cast<int64_t>(pts[i - 1].x));
      env.va[r] = row_y[r];
      env.vf[r] = best * best;
    }
    const size_t k = LowerEnvelope(m, env.va.data(), env.vf.data(), env.zn.data(), env.zd.data());
    EvaluateEnvelope(
        k, env.va.data(), env.vf.data(), env.zn.data(), env.zd.data(), -kHalf + kCentreOffset, d2);
    for (int row = 0; row < kSide; ++row) {
      out[static_cast<size_t>(row) * kSide + column] = ToUnits(d2[row]);
    }
  }
}

}  // namespace handdb
