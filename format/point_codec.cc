#include "format/point_codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <limits>

namespace handdb {
namespace {

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

struct Code {
  uint16_t bits = 0;  // bit-reversed (the stream is least significant bit first)
  uint8_t length = 0;
};

struct Table {
  std::array<Code, kNumSymbols> codes[2];
  // Decoding: the next kMaxCodeLength bits -> symbol (low byte) and length (high byte).
  std::array<uint16_t, 1u << kMaxCodeLength> decode[2];
  // Encoding preference: symbols by code length (then symbol), shortest first.
  std::array<uint8_t, 8> order[2];
};

uint16_t Reverse(uint16_t code, int length) {
  uint16_t out = 0;
  for (int i = 0; i < length; ++i) out |= ((code >> i) & 1u) << (length - 1 - i);
  return out;
}

Table MakeTable() {
  Table t{};
  for (int c = 0; c < 2; ++c) {
    std::array<int, kNumSymbols> by_length{};
    for (int s = 0; s < kNumSymbols; ++s) by_length[s] = s;
    std::stable_sort(by_length.begin(), by_length.end(), [&](int a, int b) {
      return kCodeLengths[c][a] < kCodeLengths[c][b];
    });
    uint32_t code = 0;
    int prev_length = kCodeLengths[c][by_length[0]];
    for (int i = 0; i < kNumSymbols; ++i) {
      const int s = by_length[i];
      const int length = kCodeLengths[c][s];
      code <<= (length - prev_length);
      prev_length = length;
      t.codes[c][s] = {Reverse(static_cast<uint16_t>(code), length), static_cast<uint8_t>(length)};
      const uint32_t step = 1u << length;
      for (uint32_t fill = t.codes[c][s].bits; fill < (1u << kMaxCodeLength); fill += step) {
        t.decode[c][fill] = static_cast<uint16_t>(s | (length << 8));
      }
      ++code;
    }
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

void PutVarint(uint64_t v, std::string* out) {
  while (v >= 0x80) {
    out->push_back(static_cast<char>((v & 0x7f) | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<char>(v));
}

uint64_t ZigZag(int64_t v) { return (static_cast<uint64_t>(v) << 1) ^ (v < 0 ? ~0ull : 0ull); }
int64_t UnZigZag(uint64_t v) { return static_cast<int64_t>(v >> 1) ^ -static_cast<int64_t>(v & 1); }

class BitWriter {
 public:
  explicit BitWriter(std::string* out) : out_(out) {}
  void Put(uint64_t bits, int count) {  // count <= 32
    acc_ |= bits << fill_;
    fill_ += count;
    written_ += count;
    while (fill_ >= 8) {
      out_->push_back(static_cast<char>(acc_ & 0xff));
      acc_ >>= 8;
      fill_ -= 8;
    }
  }
  void PutGamma(uint32_t v) {  // v >= 1: floor(log2 v) zeros, a one, the bits below the top one
    const int n = std::bit_width(v) - 1;
    Put(0, n);
    Put(1, 1);
    Put(v & ((1u << n) - 1), n);
  }
  void Flush() {
    if (fill_ > 0) out_->push_back(static_cast<char>(acc_ & 0xff));
    acc_ = 0;
    fill_ = 0;
  }
  uint64_t written() const { return written_; }

 private:
  std::string* out_;
  uint64_t acc_ = 0;
  int fill_ = 0;
  uint64_t written_ = 0;
};

class BitReader {
 public:
  explicit BitReader(std::span<const uint8_t> bytes) : bytes_(bytes) {}
  // The next `count` (<= 32) bits without consuming them; zeros past the end.
  uint32_t Peek(int count) {
    if (fill_ < count) Refill();
    return static_cast<uint32_t>(acc_ & ((1ull << count) - 1));
  }
  void Skip(int count) {
    acc_ >>= count;
    fill_ -= count;
    consumed_ += static_cast<uint64_t>(count);
  }
  uint32_t Get(int count) {
    if (count == 0) return 0;
    const uint32_t v = Peek(count);
    Skip(count);
    return v;
  }
  // Elias gamma; false on more than 31 leading zeros (no such value is ever written).
  bool GetGamma(uint32_t* v) {
    const uint32_t head = Peek(32);
    if (head == 0) return false;
    const int zeros = std::countr_zero(head);
    Skip(zeros + 1);
    *v = (1u << zeros) | Get(zeros);
    return true;
  }
  bool overrun() const { return consumed_ > 8 * bytes_.size(); }
  uint64_t consumed() const { return consumed_; }

 private:
  // Tops the accumulator up to at least 57 bits (whole bytes), eight at a time when it can.
  void Refill() {
    const int take = (63 - fill_) / 8;
    if (pos_ + 8 <= bytes_.size()) {
      uint64_t word = 0;
      std::memcpy(&word, bytes_.data() + pos_, 8);  // little-endian (the format's byte order)
      if (take < 8) word &= (1ull << (8 * take)) - 1;
      acc_ |= word << fill_;
    } else {
      for (int i = 0; i < take; ++i) {
        const uint64_t byte = pos_ + i < bytes_.size() ? bytes_[pos_ + i] : 0;
        acc_ |= byte << (fill_ + 8 * i);
      }
    }
    pos_ += static_cast<size_t>(take);
    fill_ += 8 * take;
  }

  std::span<const uint8_t> bytes_;
  size_t pos_ = 0;
  uint64_t acc_ = 0;
  int fill_ = 0;
  uint64_t consumed_ = 0;
};

bool GetVarint(std::span<const uint8_t> code, size_t* pos, uint64_t* v) {
  uint64_t out = 0;
  for (int shift = 0; shift < 64; shift += 7) {
    if (*pos >= code.size()) return false;
    const uint8_t byte = code[(*pos)++];
    out |= static_cast<uint64_t>(byte & 0x7f) << shift;
    if (!(byte & 0x80)) {
      *v = out;
      return true;
    }
  }
  return false;
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
  PutVarint(p.size(), out);
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
  PutVarint(ZigZag(min_col), out);
  PutVarint(ZigZag(min_row), out);
  PutVarint(static_cast<uint64_t>(width - 1), out);
  PutVarint(static_cast<uint64_t>(height - 1), out);
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
  BitWriter bits(out);
  int64_t prev_row = min_row, prev_col = min_col;
  bool first = true;
  for (const LatticePixel& start : p) {
    if (at(start.col, start.row) != 1) continue;
    const uint64_t before = bits.written();
    const int64_t drow = start.row - prev_row;
    bits.PutGamma(static_cast<uint32_t>(drow + 1));
    if (drow == 0 && !first) {
      bits.PutGamma(static_cast<uint32_t>(start.col - prev_col));
    } else {
      bits.PutGamma(static_cast<uint32_t>(start.col - min_col + 1));
    }
    first = false;
    prev_row = start.row;
    prev_col = start.col;
    at(start.col, start.row) = 2;
    if (stats) {
      stats->start_bits += bits.written() - before;
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
      const Code code = table.codes[context][symbol];
      bits.Put(code.bits, code.length);
      if (stats) {
        stats->move_bits += code.length;
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
  bits.Flush();
  return Status::Ok();
}

Status DecodeLatticePixels(std::span<const uint8_t> code, std::vector<LatticePixel>* out) {
  out->clear();
  size_t pos = 0;
  uint64_t n = 0;
  if (!GetVarint(code, &pos, &n)) {
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
  if (!GetVarint(code, &pos, &zc) || !GetVarint(code, &pos, &zr) || !GetVarint(code, &pos, &w1) ||
      !GetVarint(code, &pos, &h1)) {
    return Status(StatusCode::kTruncated,
                  "point code: bounding box cut off at byte " + std::to_string(pos));
  }
  const int64_t min_col = UnZigZag(zc), min_row = UnZigZag(zr);
  if (w1 >= static_cast<uint64_t>(kMaxLatticeSide) ||
      h1 >= static_cast<uint64_t>(kMaxLatticeSide) ||
      min_col < std::numeric_limits<int32_t>::min() ||
      min_row < std::numeric_limits<int32_t>::min() ||
      min_col + static_cast<int64_t>(w1) > std::numeric_limits<int32_t>::max() ||
      min_row + static_cast<int64_t>(h1) > std::numeric_limits<int32_t>::max()) {
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
  BitReader bits(stream);
  const Table& table = CodeTable();
  auto bad = [&](const std::string& what) {
    return Status(StatusCode::kOutOfRange,
                  "point code: " + what + " at byte " + std::to_string(pos + bits.consumed() / 8) +
                      " (pixel " + std::to_string(out->size()) + " of " + std::to_string(n) + ")");
  };
  uint64_t decoded = 0;
  int64_t prev_x = 0, prev_y = 0;
  bool first = true;
  while (decoded < n) {
    uint32_t drow1 = 0, col = 0;
    if (!bits.GetGamma(&drow1) || !bits.GetGamma(&col)) return bad("bad chain start");
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
      const uint16_t entry = table.decode[context][bits.Peek(kMaxCodeLength)];
      bits.Skip(entry >> 8);
      const int symbol = entry & 0xff;
      if (bits.overrun()) {
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
  if (bits.overrun()) {
    return Status(StatusCode::kTruncated, "point code: ends inside its last chain");
  }
  const uint64_t used_bytes = (bits.consumed() + 7) / 8;
  if (used_bytes != stream.size()) {
    return Status(StatusCode::kSizeMismatch,
                  "point code: " + std::to_string(stream.size()) + " stream bytes, the " +
                      std::to_string(n) + " pixels use " + std::to_string(used_bytes));
  }
  if (bits.consumed() % 8 != 0 && (stream.back() >> (bits.consumed() % 8)) != 0) {
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
