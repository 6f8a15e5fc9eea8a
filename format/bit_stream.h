// Bit-level building blocks of the format's codecs (format/point_codec.h, format/field_codec.h):
// varints, a least-significant-bit-first bit stream, canonical prefix codes from code lengths.
// Internal to format/.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>

namespace handdb::bits {

// A code held in a std::string, as the decoders read it.
inline std::span<const uint8_t> AsBytes(const std::string& s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

inline void PutVarint(uint64_t v, std::string* out) {
  while (v >= 0x80) {
    out->push_back(static_cast<char>((v & 0x7f) | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<char>(v));
}

inline uint64_t ZigZag(int64_t v) {
  return (static_cast<uint64_t>(v) << 1) ^ (v < 0 ? ~0ull : 0ull);
}
inline int64_t UnZigZag(uint64_t v) {
  return static_cast<int64_t>(v >> 1) ^ -static_cast<int64_t>(v & 1);
}

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

inline bool GetVarint(std::span<const uint8_t> code, size_t* pos, uint64_t* v) {
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

// A canonical prefix code over kSymbols symbols given their lengths (at most kMaxLength bits,
// Kraft sum exactly 1), written bit-reversed so the least-significant-bit-first stream decodes
// with one table lookup of the next kMaxLength bits.
template <int kSymbols, int kMaxLength>
struct PrefixCode {
  struct Code {
    uint16_t bits = 0;
    uint8_t length = 0;
  };
  std::array<Code, kSymbols> codes{};
  std::array<uint16_t, 1u << kMaxLength> decode{};  // symbol | length << 8

  static PrefixCode FromLengths(const uint8_t (&lengths)[kSymbols]) {
    PrefixCode t;
    std::array<int, kSymbols> by_length{};
    for (int s = 0; s < kSymbols; ++s) by_length[s] = s;
    std::stable_sort(
        by_length.begin(), by_length.end(), [&](int a, int b) { return lengths[a] < lengths[b]; });
    uint32_t code = 0;
    int prev_length = lengths[by_length[0]];
    for (int i = 0; i < kSymbols; ++i) {
      const int s = by_length[i];
      const int length = lengths[s];
      code <<= (length - prev_length);
      prev_length = length;
      uint16_t reversed = 0;
      for (int b = 0; b < length; ++b) reversed |= ((code >> b) & 1u) << (length - 1 - b);
      t.codes[s] = {reversed, static_cast<uint8_t>(length)};
      for (uint32_t fill = reversed; fill < (1u << kMaxLength); fill += 1u << length) {
        t.decode[fill] = static_cast<uint16_t>(s | (length << 8));
      }
      ++code;
    }
    return t;
  }
  void Put(int symbol, BitWriter* out) const { out->Put(codes[symbol].bits, codes[symbol].length); }
  // The next symbol (past the end of the stream the reader reads zeros; check overrun()).
  int Get(BitReader* in) const {
    const uint16_t entry = decode[in->Peek(kMaxLength)];
    in->Skip(entry >> 8);
    return entry & 0xff;
  }
};

}  // namespace handdb::bits
