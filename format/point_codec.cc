#include "format/point_codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>

#include "format/bit_stream.h"

namespace handdb {
namespace {

// A bounding box (its first column and row, its width and height minus one, each below
// kMaxLatticeSide) whose corners are all int32. The first corner is checked before the sums,
// which a damaged code could otherwise carry past int64.
bool BoxInInt32(int64_t min_col, int64_t min_row, uint64_t w1, uint64_t h1) {
  constexpr int64_t kMin = std::numeric_limits<int32_t>::min();
  constexpr int64_t kMax = std::numeric_limits<int32_t>::max();
  return min_col >= kMin && min_row >= kMin && min_col <= kMax && min_row <= kMax &&
         min_col + static_cast<int64_t>(w1) <= kMax && min_row + static_cast<int64_t>(h1) <= kMax;
}

// Moves: 0 E, 1 SE, 2 S, 3 SW, 4 W, 5 NW, 6 N, 7 NE (image coordinates, y down).
constexpr int kDx[8] = {1, 1, 0, -1, -1, -1, 0, 1};
constexpr int kDy[8] = {0, 1, 1, 1, 0, -1, -1, -1};
constexpr int kEnd = 8;  // symbol: end of chain
constexpr int kNumSymbols = 9;
constexpr int kMaxCodeLength = 12;

// Code lengths per context (after an axial move / after a diagonal move) and symbol (the move
// relative to the previous one, 0-7, then end of chain): canonical Huffman lengths of the
// symbol counts of the paper database's 2,236 views (bench/point_codec_bench prints them).
constexpr uint8_t kCodeLengths[2][kNumSymbols] = {
    {1, 2, 5, 6, 8, 8, 7, 3, 4},
    {2, 2, 4, 6, 7, 7, 5, 2, 3},
};

using bits::BitReader;
using bits::BitWriter;
using Code = bits::PrefixCode<kNumSymbols, kMaxCodeLength>;

struct Table {
  Code code[2];  // per context
  // Encoding preference: symbols by code length (then symbol), shortest first.
  std::array<uint8_t, 8> order[2];
};

Table MakeTable() {
  Table t{};
  for (int c = 0; c < 2; ++c) {
    t.code[c] = Code::FromLengths(kCodeLengths[c]);
    std::array<int, kNumSymbols> by_length{};
    for (int s = 0; s < kNumSymbols; ++s) by_length[s] = s;
    std::stable_sort(by_length.begin(), by_length.end(), [&](int a, int b) {
      return kCodeLengths[c][a] < kCodeLengths[c][b];
    });
    int k = 0;
    for (int s : by_length) {
      if (s != kEnd) t.order[c][k++] = static_cast<uint8_t>(s);
    }
  }
  return t;
}

const Table& CodeTable() {
  static const Table table = MakeTable();
  return table;
}

bool Diagonal(int move) { return (move & 1) != 0; }

}  // namespace

Status EncodeLatticePixels(std::span<const LatticePixel> pixels, std::string* out) {
  return EncodeLatticePixels(pixels, out, nullptr);
}

Status EncodeLatticePixels(std::span<const LatticePixel> pixels,
                           std::string* out,
                           LatticeCodeStats* stats) {
  std::vector<LatticePixel> p(pixels.begin(), pixels.end());
  std::sort(p.begin(), p.end(), [](const LatticePixel& a, const LatticePixel& b) {
    return a.row != b.row ? a.row < b.row : a.col < b.col;
  });
  p.erase(std::unique(p.begin(), p.end()), p.end());
  const size_t header_start = out->size();
  bits::PutVarint(p.size(), out);
  if (p.empty()) {
    if (stats) stats->header_bytes += out->size() - header_start;
    return Status::Ok();
  }
  int64_t min_col = p[0].col, max_col = p[0].col;
  for (const LatticePixel& q : p) {
    min_col = std::min<int64_t>(min_col, q.col);
    max_col = std::max<int64_t>(max_col, q.col);
  }
  const int64_t min_row = p.front().row, max_row = p.back().row;
  const int64_t width = max_col - min_col + 1, height = max_row - min_row + 1;
  if (width > kMaxLatticeSide || height > kMaxLatticeSide) {
    return Status(StatusCode::kOutOfRange,
                  "edge pixels span " + std::to_string(width) + " x " + std::to_string(height) +
                      " px, more than the codec's " + std::to_string(kMaxLatticeSide));
  }
  bits::PutVarint(bits::ZigZag(min_col), out);
  bits::PutVarint(bits::ZigZag(min_row), out);
  bits::PutVarint(static_cast<uint64_t>(width - 1), out);
  bits::PutVarint(static_cast<uint64_t>(height - 1), out);
  if (stats) {
    stats->header_bytes += out->size() - header_start;
    stats->pixels += p.size();
  }

  // 0: not an edge pixel, 1: an edge pixel not yet coded, 2: coded.
  std::vector<uint8_t> state(static_cast<size_t>(width * height), 0);
  auto at = [&](int64_t c, int64_t r) -> uint8_t& {
    return state[static_cast<size_t>((r - min_row) * width + (c - min_col))];
  };
  for (const LatticePixel& q : p) at(q.col, q.row) = 1;

  const Table& table = CodeTable();
  BitWriter writer(out);
  int64_t prev_row = min_row, prev_col = min_col;
  bool first = true;
  for (const LatticePixel& start : p) {
    if (at(start.col, start.row) != 1) continue;
    const uint64_t before = writer.written();
    const int64_t drow = start.row - prev_row;
    writer.PutGamma(static_cast<uint32_t>(drow + 1));
    if (drow == 0 && !first) {
      writer.PutGamma(static_cast<uint32_t>(start.col - prev_col));
    } else {
      writer.PutGamma(static_cast<uint32_t>(start.col - min_col + 1));
    }
    first = false;
    prev_row = start.row;
    prev_col = start.col;
    at(start.col, start.row) = 2;
    if (stats) {
      stats->start_bits += writer.written() - before;
      ++stats->chains;
    }
    // Walk: the cheapest move to a pixel not yet coded, until there is none.
    int64_t c = start.col, r = start.row;
    int prev_move = 0;
    int context = 0;
    for (;;) {
      int symbol = kEnd;
      for (const uint8_t rel : table.order[context]) {
        const int move = (prev_move + rel) & 7;
        const int64_t nc = c + kDx[move], nr = r + kDy[move];
        if (nc < min_col || nc > max_col || nr < min_row || nr > max_row) continue;
        if (at(nc, nr) != 1) continue;
        symbol = rel;
        break;
      }
      table.code[context].Put(symbol, &writer);
      if (stats) {
        stats->move_bits += table.code[context].codes[symbol].length;
        ++stats->symbols[context][symbol];
      }
      if (symbol == kEnd) break;
      prev_move = (prev_move + symbol) & 7;
      context = Diagonal(prev_move) ? 1 : 0;
      c += kDx[prev_move];
      r += kDy[prev_move];
      at(c, r) = 2;
    }
  }
  writer.Flush();
  return Status::Ok();
}

Status DecodeLatticePixels(std::span<const uint8_t> code, std::vector<LatticePixel>* out) {
  out->clear();
  size_t pos = 0;
  uint64_t n = 0;
  if (!bits::GetVarint(code, &pos, &n)) {
    return Status(StatusCode::kTruncated, "point code: pixel count cut off at byte 0");
  }
  if (n == 0) {
    if (pos != code.size()) {
      return Status(StatusCode::kSizeMismatch,
                    "point code: " + std::to_string(code.size() - pos) +
                        " byte(s) after an empty view's count");
    }
    return Status::Ok();
  }
  uint64_t zc = 0, zr = 0, w1 = 0, h1 = 0;
  if (!bits::GetVarint(code, &pos, &zc) || !bits::GetVarint(code, &pos, &zr) ||
      !bits::GetVarint(code, &pos, &w1) || !bits::GetVarint(code, &pos, &h1)) {
    return Status(StatusCode::kTruncated,
                  "point code: bounding box cut off at byte " + std::to_string(pos));
  }
  const int64_t min_col = bits::UnZigZag(zc), min_row = bits::UnZigZag(zr);
  if (w1 >= static_cast<uint64_t>(kMaxLatticeSide) ||
      h1 >= static_cast<uint64_t>(kMaxLatticeSide) || !BoxInInt32(min_col, min_row, w1, h1)) {
    return Status(StatusCode::kOutOfRange,
                  "point code: bounding box " + std::to_string(w1 + 1) + " x " +
                      std::to_string(h1 + 1) + " at (" + std::to_string(min_col) + ", " +
                      std::to_string(min_row) + ") is out of range");
  }
  const int64_t width = static_cast<int64_t>(w1) + 1, height = static_cast<int64_t>(h1) + 1;
  if (n > static_cast<uint64_t>(width * height)) {
    return Status(StatusCode::kSizeMismatch,
                  "point code: " + std::to_string(n) + " pixels do not fit a " +
                      std::to_string(width) + " x " + std::to_string(height) + " box");
  }
  // One bit per box pixel: coded or not.
  const size_t words_per_row = static_cast<size_t>((width + 63) / 64);
  std::vector<uint64_t> grid(words_per_row * static_cast<size_t>(height), 0);
  auto test_and_set = [&](int64_t x, int64_t y) {  // box coordinates; true if already set
    uint64_t& word = grid[static_cast<size_t>(y) * words_per_row + static_cast<size_t>(x >> 6)];
    const uint64_t bit = 1ull << (x & 63);
    const bool was = (word & bit) != 0;
    word |= bit;
    return was;
  };
  const std::span<const uint8_t> stream = code.subspan(pos);
  BitReader reader(stream);
  const Table& table = CodeTable();
  auto bad = [&](const std::string& what) {
    return Status(StatusCode::kOutOfRange,
                  "point code: " + what + " at byte " +
                      std::to_string(pos + reader.consumed() / 8) + " (pixel " +
                      std::to_string(out->size()) + " of " + std::to_string(n) + ")");
  };
  uint64_t decoded = 0;
  int64_t prev_x = 0, prev_y = 0;
  bool first = true;
  while (decoded < n) {
    uint32_t drow1 = 0, col = 0;
    if (!reader.GetGamma(&drow1) || !reader.GetGamma(&col)) return bad("bad chain start");
    const int64_t y = prev_y + static_cast<int64_t>(drow1) - 1;
    const int64_t x = (drow1 == 1 && !first) ? prev_x + col : static_cast<int64_t>(col) - 1;
    if ((first && drow1 != 1) || y >= height || x < 0 || x >= width) {
      return bad("chain start outside the box");
    }
    first = false;
    prev_x = x;
    prev_y = y;
    if (test_and_set(x, y)) return bad("chain start on a pixel coded before");
    ++decoded;
    int64_t cx = x, cy = y;
    int prev_move = 0, context = 0;
    for (;;) {
      const int symbol = table.code[context].Get(&reader);
      if (reader.overrun()) {
        return Status(StatusCode::kTruncated,
                      "point code: ends inside a chain (" + std::to_string(decoded) + " of " +
                          std::to_string(n) + " pixels decoded)");
      }
      if (symbol == kEnd) break;
      prev_move = (prev_move + symbol) & 7;
      context = Diagonal(prev_move) ? 1 : 0;
      cx += kDx[prev_move];
      cy += kDy[prev_move];
      if (cx < 0 || cx >= width || cy < 0 || cy >= height) return bad("move off the box");
      if (test_and_set(cx, cy)) return bad("move onto a pixel coded before");
      if (++decoded > n) return bad("more pixels than the count");
    }
  }
  if (reader.overrun()) {
    return Status(StatusCode::kTruncated, "point code: ends inside its last chain");
  }
  const uint64_t used_bytes = (reader.consumed() + 7) / 8;
  if (used_bytes != stream.size()) {
    return Status(StatusCode::kSizeMismatch,
                  "point code: " + std::to_string(stream.size()) + " stream bytes, the " +
                      std::to_string(n) + " pixels use " + std::to_string(used_bytes));
  }
  if (reader.consumed() % 8 != 0 && (stream.back() >> (reader.consumed() % 8)) != 0) {
    return Status(StatusCode::kNonZeroReserved, "point code: padding bits are not zero");
  }
  // Raster order: the set bits row by row.
  out->reserve(n);
  for (int64_t y = 0; y < height; ++y) {
    const uint64_t* row = &grid[static_cast<size_t>(y) * words_per_row];
    for (size_t wi = 0; wi < words_per_row; ++wi) {
      for (uint64_t word = row[wi]; word != 0; word &= word - 1) {
        const int64_t x = static_cast<int64_t>(wi * 64) + std::countr_zero(word);
        out->push_back({static_cast<int32_t>(min_col + x), static_cast<int32_t>(min_row + y)});
      }
    }
  }
  return Status::Ok();
}

}  // namespace handdb

namespace handdb {
namespace {

bool YxLess(const PointQ& a, const PointQ& b) { return a.y != b.y ? a.y < b.y : a.x < b.x; }

// The record's normalisation, as the lattice <-> point maps use it.
struct Lattice {
  double s = 0, cx = 0, cy = 0;
  bool usable = false;
  Lattice(float scale, std::array<float, 2> centre)
      : s(static_cast<double>(scale) * kPointScale), cx(centre[0]), cy(centre[1]) {
    // Bounded so that every product below stays far inside int64.
    usable = std::isfinite(s) && s >= 1 && s <= 1e6 && std::isfinite(cx) && std::isfinite(cy) &&
             std::fabs(cx) < 1e8 && std::fabs(cy) < 1e8;
  }
  // The pixel a point came from (false when it is far outside int32).
  bool PixelOf(const PointQ& p, LatticePixel* q) const {
    const double col = std::nearbyint(p.x / s + cx - 0.5), row = std::nearbyint(p.y / s + cy - 0.5);
    if (std::fabs(col) > 1e9 || std::fabs(row) > 1e9) return false;
    *q = {static_cast<int32_t>(col), static_cast<int32_t>(row)};
    return true;
  }
  // The point a pixel gives (the converter's NormalisePixels, in the record's float values).
  void PointOf(const LatticePixel& q, int64_t* x, int64_t* y) const {
    *x = static_cast<int64_t>(std::nearbyint((q.col + 0.5 - cx) * s));
    *y = static_cast<int64_t>(std::nearbyint((q.row + 0.5 - cy) * s));
  }
};

constexpr uint8_t kModeLattice = 0;
// Largest |dx|, |dy| of a mode-0 correction (PointQ units).
constexpr int64_t kMaxCorrection = 1;
// The zigzag code of the largest step between two int16 values (65535): larger ones are damage.
constexpr uint64_t kMaxZigZagStep = 2 * 65535;
constexpr uint8_t kModeRaw = 1;

void EncodeRaw(std::span<const PointQ> points, std::string* out) {
  out->push_back(static_cast<char>(kModeRaw));
  bits::PutVarint(points.size(), out);
  int64_t prev_x = 0, prev_y = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    const int64_t dy = points[i].y - prev_y;
    bits::PutVarint(bits::ZigZag(dy), out);
    if (i > 0 && dy == 0) {
      bits::PutVarint(bits::ZigZag(points[i].x - prev_x), out);
    } else {
      bits::PutVarint(bits::ZigZag(points[i].x), out);
    }
    prev_x = points[i].x;
    prev_y = points[i].y;
  }
}

Status OutOfRange(const std::string& what) {
  return Status(StatusCode::kOutOfRange, "point code: " + what);
}

Status DecodeRaw(std::span<const uint8_t> code, size_t pos, std::vector<PointQ>* out) {
  uint64_t n = 0;
  if (!bits::GetVarint(code, &pos, &n)) {
    return Status(StatusCode::kTruncated, "point code: count cut off");
  }
  if (n > code.size()) {  // every point takes at least two bytes
    return Status(StatusCode::kSizeMismatch,
                  "point code: " + std::to_string(n) + " points cannot fit " +
                      std::to_string(code.size()) + " bytes");
  }
  out->reserve(n);
  int64_t prev_x = 0, prev_y = 0;
  for (uint64_t i = 0; i < n; ++i) {
    uint64_t zy = 0, xv = 0;
    if (!bits::GetVarint(code, &pos, &zy) || !bits::GetVarint(code, &pos, &xv)) {
      return Status(
          StatusCode::kTruncated,
          "point code: point " + std::to_string(i) + " of " + std::to_string(n) + " cut off");
    }
    if (zy > kMaxZigZagStep || xv > kMaxZigZagStep) {
      return OutOfRange("point " + std::to_string(i) + " steps outside int16");
    }
    const int64_t dy = bits::UnZigZag(zy);
    const int64_t y = prev_y + dy;
    const int64_t x = (i > 0 && dy == 0) ? prev_x + bits::UnZigZag(xv) : bits::UnZigZag(xv);
    if (x < INT16_MIN || x > INT16_MAX || y < INT16_MIN || y > INT16_MAX) {
      return OutOfRange("point " + std::to_string(i) + " (" + std::to_string(x) + ", " +
                        std::to_string(y) + ") is outside int16");
    }
    out->push_back({static_cast<int16_t>(x), static_cast<int16_t>(y)});
    prev_x = x;
    prev_y = y;
  }
  if (pos != code.size()) {
    return Status(StatusCode::kSizeMismatch,
                  "point code: " + std::to_string(code.size() - pos) + " byte(s) after the points");
  }
  return Status::Ok();
}

// Mode 0 after its mode byte: the lattice code, then the corrections.
Status DecodeLatticeMode(std::span<const uint8_t> code,
                         const Lattice& lattice,
                         std::vector<PointQ>* out) {
  if (!lattice.usable) return OutOfRange("lattice code with an unusable scale or centre");
  size_t pos = 0;
  uint64_t lattice_bytes = 0;
  if (!bits::GetVarint(code, &pos, &lattice_bytes) || lattice_bytes > code.size() - pos) {
    return Status(StatusCode::kTruncated, "point code: lattice code length cut off or too long");
  }
  std::vector<LatticePixel> pixels;
  HANDDB_RETURN_IF_ERROR(
      DecodeLatticePixels(code.subspan(pos, static_cast<size_t>(lattice_bytes)), &pixels));
  pos += static_cast<size_t>(lattice_bytes);
  // The points the pixels give; a damaged code may give them outside int16.
  out->resize(pixels.size());
  for (size_t i = 0; i < pixels.size(); ++i) {
    int64_t x = 0, y = 0;
    lattice.PointOf(pixels[i], &x, &y);
    if (x < INT16_MIN || x > INT16_MAX || y < INT16_MIN || y > INT16_MAX) {
      return OutOfRange("pixel " + std::to_string(i) + " gives point (" + std::to_string(x) + ", " +
                        std::to_string(y) + "), outside int16");
    }
    (*out)[i] = {static_cast<int16_t>(x), static_cast<int16_t>(y)};
  }
  uint64_t corrections = 0;
  if (!bits::GetVarint(code, &pos, &corrections) || corrections > pixels.size()) {
    return Status(StatusCode::kTruncated, "point code: correction count cut off or too large");
  }
  uint64_t index = 0;
  for (uint64_t c = 0; c < corrections; ++c) {
    uint64_t step = 0, zx = 0, zy = 0;
    if (!bits::GetVarint(code, &pos, &step) || !bits::GetVarint(code, &pos, &zx) ||
        !bits::GetVarint(code, &pos, &zy)) {
      return Status(StatusCode::kTruncated,
                    "point code: correction " + std::to_string(c) + " cut off");
    }
    if (step >= pixels.size() || zx > kMaxZigZagStep || zy > kMaxZigZagStep) {
      return OutOfRange("correction " + std::to_string(c) + " is out of range");
    }
    index = c == 0 ? step : index + step;
    if ((c > 0 && step == 0) || index >= pixels.size()) {
      return OutOfRange("correction " + std::to_string(c) + " names point " +
                        std::to_string(index) + " of " + std::to_string(pixels.size()));
    }
    // A correction is the 1/16 px by which float and double normalisation round apart; anything
    // larger is damage (and would break the box bound PeekViewPoints gives).
    const int64_t dx = bits::UnZigZag(zx), dy = bits::UnZigZag(zy);
    if (dx < -kMaxCorrection || dx > kMaxCorrection || dy < -kMaxCorrection ||
        dy > kMaxCorrection) {
      return OutOfRange("correction " + std::to_string(c) + " moves point " +
                        std::to_string(index) + " by (" + std::to_string(dx) + ", " +
                        std::to_string(dy) + "), more than 1/16 px");
    }
    const int64_t x = (*out)[index].x + dx;
    const int64_t y = (*out)[index].y + dy;
    if (x < INT16_MIN || x > INT16_MAX || y < INT16_MIN || y > INT16_MAX) {
      return OutOfRange("correction " + std::to_string(c) + " moves point " +
                        std::to_string(index) + " outside int16");
    }
    (*out)[index] = {static_cast<int16_t>(x), static_cast<int16_t>(y)};
  }
  if (pos != code.size()) {
    return Status(
        StatusCode::kSizeMismatch,
        "point code: " + std::to_string(code.size() - pos) + " byte(s) after the corrections");
  }
  return Status::Ok();
}

}  // namespace

Status EncodeViewPoints(std::span<const PointQ> points,
                        float scale,
                        std::array<float, 2> centre,
                        std::string* out,
                        int* mode) {
  std::string raw;
  EncodeRaw(points, &raw);
  std::string lattice_code;
  const Lattice lattice(scale, centre);
  // The lattice mode gives points in (y, x) order, without repeats: only for such views.
  bool lattice_ok =
      lattice.usable && !points.empty() &&
      std::adjacent_find(points.begin(), points.end(), [](const PointQ& a, const PointQ& b) {
        return !YxLess(a, b);
      }) == points.end();
  std::vector<LatticePixel> pixels;
  if (lattice_ok) {
    pixels.reserve(points.size());
    for (const PointQ& p : points) {
      LatticePixel q;
      if (!lattice.PixelOf(p, &q)) {
        lattice_ok = false;
        break;
      }
      pixels.push_back(q);
    }
  }
  // The chain code's order: raster order, in which the pixels must be as many as the points
  // (two points on one pixel cannot both be coded).
  std::vector<LatticePixel> raster = std::move(pixels);
  std::sort(raster.begin(), raster.end(), [](const LatticePixel& a, const LatticePixel& b) {
    return a.row != b.row ? a.row < b.row : a.col < b.col;
  });
  lattice_ok = lattice_ok && std::adjacent_find(raster.begin(), raster.end()) == raster.end();
  std::string chain;
  if (lattice_ok && EncodeLatticePixels(raster, &chain).ok()) {
    lattice_code.push_back(static_cast<char>(kModeLattice));
    bits::PutVarint(chain.size(), &lattice_code);
    lattice_code += chain;
    std::string fixes;
    uint64_t count = 0;
    size_t last = 0;
    for (size_t i = 0; i < raster.size(); ++i) {
      int64_t x = 0, y = 0;
      lattice.PointOf(raster[i], &x, &y);
      if (x == points[i].x && y == points[i].y) continue;
      bits::PutVarint(count == 0 ? i : i - last, &fixes);
      bits::PutVarint(bits::ZigZag(points[i].x - x), &fixes);
      bits::PutVarint(bits::ZigZag(points[i].y - y), &fixes);
      last = i;
      ++count;
    }
    bits::PutVarint(count, &lattice_code);
    lattice_code += fixes;
    // The guarantee: mode 0 only if it decodes to exactly these points.
    std::vector<PointQ> back;
    lattice_ok =
        DecodeViewPoints(bits::AsBytes(lattice_code), scale, centre, &back).ok() &&
        back.size() == points.size() &&
        std::equal(back.begin(), back.end(), points.begin(), [](const PointQ& a, const PointQ& b) {
          return a.x == b.x && a.y == b.y;
        });
  } else {
    lattice_ok = false;
  }
  const bool use_lattice = lattice_ok && lattice_code.size() <= raw.size();
  *out += use_lattice ? lattice_code : raw;
  if (mode) *mode = use_lattice ? kModeLattice : kModeRaw;
  return Status::Ok();
}

Status PeekViewPoints(std::span<const uint8_t> code,
                      float scale,
                      std::array<float, 2> centre,
                      ViewPointsExtent* out) {
  *out = ViewPointsExtent{};
  if (code.empty()) return Status(StatusCode::kTruncated, "point code: empty");
  if (code[0] == kModeRaw) return Status::Ok();  // known only by decoding
  if (code[0] != kModeLattice) return OutOfRange("unknown mode " + std::to_string(code[0]));
  const Lattice lattice(scale, centre);
  if (!lattice.usable) return OutOfRange("lattice code with an unusable scale or centre");
  size_t pos = 1;
  uint64_t lattice_bytes = 0, n = 0, zc = 0, zr = 0, w1 = 0, h1 = 0;
  if (!bits::GetVarint(code, &pos, &lattice_bytes) || !bits::GetVarint(code, &pos, &n) ||
      (n > 0 && (!bits::GetVarint(code, &pos, &zc) || !bits::GetVarint(code, &pos, &zr) ||
                 !bits::GetVarint(code, &pos, &w1) || !bits::GetVarint(code, &pos, &h1)))) {
    return Status(StatusCode::kTruncated, "point code: lattice header cut off");
  }
  out->peeked = true;
  out->count = n;
  out->sorted = true;  // a mode-0 decode is sorted by (y, x), or an error
  if (n == 0) return Status::Ok();
  if (w1 >= static_cast<uint64_t>(kMaxLatticeSide) ||
      h1 >= static_cast<uint64_t>(kMaxLatticeSide)) {
    return OutOfRange("bounding box out of range");
  }
  const int64_t min_col = bits::UnZigZag(zc), min_row = bits::UnZigZag(zr);
  if (!BoxInInt32(min_col, min_row, w1, h1)) {
    return OutOfRange("bounding box out of range");
  }
  // PointOf is monotonic in the column and the row: the box's corners bound every pixel's point.
  int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  lattice.PointOf({static_cast<int32_t>(min_col), static_cast<int32_t>(min_row)}, &x0, &y0);
  lattice.PointOf({static_cast<int32_t>(min_col + static_cast<int64_t>(w1)),
                   static_cast<int32_t>(min_row + static_cast<int64_t>(h1))},
                  &x1,
                  &y1);
  const int64_t bound =
      std::max({std::abs(x0), std::abs(x1), std::abs(y0), std::abs(y1)}) + kMaxCorrection;
  out->max_abs_bound = static_cast<int32_t>(std::min<int64_t>(bound, INT32_MAX));
  return Status::Ok();
}

Status DecodeViewPoints(std::span<const uint8_t> code,
                        float scale,
                        std::array<float, 2> centre,
                        std::vector<PointQ>* out) {
  out->clear();
  if (code.empty()) return Status(StatusCode::kTruncated, "point code: empty");
  if (code[0] == kModeRaw) return DecodeRaw(code, 1, out);
  if (code[0] != kModeLattice) return OutOfRange("unknown mode " + std::to_string(code[0]));
  HANDDB_RETURN_IF_ERROR(DecodeLatticeMode(code.subspan(1), Lattice(scale, centre), out));
  for (size_t i = 1; i < out->size(); ++i) {
    if (!YxLess((*out)[i - 1], (*out)[i])) {
      return Status(StatusCode::kBadLayout,
                    "point code: decoded points " + std::to_string(i - 1) + " and " +
                        std::to_string(i) + " are not sorted by (y, x) and unique");
    }
  }
  return Status::Ok();
}

}  // namespace handdb
