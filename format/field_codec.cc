#include "format/field_codec.h"

#include <algorithm>

#include "format/bit_stream.h"

namespace handdb {
namespace {

constexpr int kFieldMaxResidual = 15;
constexpr int kFieldEscape = 2 * kFieldMaxResidual + 1;  // symbol: the cell's 8 bits follow
constexpr int kFieldSymbols = kFieldEscape + 1;
constexpr int kFieldMaxCodeLength = 12;

// Code lengths of residuals -15..15, then the escape: canonical Huffman lengths of the
// paper database's 2,236 fields (4.1M cells: 50% zero, 31% +-1; 0.1% escaped).
constexpr uint8_t kFieldCodeLengths[kFieldSymbols] = {11, 11, 10, 9, 9, 9,  8,  8,  7,  7, 7,
                                                      6,  5,  4,  3, 1, 3,  5,  6,  6,  7, 7,
                                                      7,  8,  8,  9, 9, 10, 10, 11, 11, 10};

using FieldPrefixCode = bits::PrefixCode<kFieldSymbols, kFieldMaxCodeLength>;

const FieldPrefixCode& FieldCode() {
  static const FieldPrefixCode code = FieldPrefixCode::FromLengths(kFieldCodeLengths);
  return code;
}

int PredictCell(const uint8_t* f, int x, int y) {
  constexpr int kSide = CoarseGrid::kSide;
  if (y == 0) return x == 0 ? 0 : f[x - 1];
  if (x == 0) return f[(y - 1) * kSide];
  const int w = f[y * kSide + x - 1], n = f[(y - 1) * kSide + x], nw = f[(y - 1) * kSide + x - 1];
  return std::clamp(w + n - nw, 0, 255);
}

}  // namespace

void EncodeCoarseField(std::span<const uint8_t, CoarseGrid::kCells> field, std::string* out) {
  const FieldPrefixCode& code = FieldCode();
  bits::BitWriter writer(out);
  for (int y = 0; y < CoarseGrid::kSide; ++y) {
    for (int x = 0; x < CoarseGrid::kSide; ++x) {
      const int value = field[static_cast<size_t>(y * CoarseGrid::kSide + x)];
      const int residual = value - PredictCell(field.data(), x, y);
      if (residual >= -kFieldMaxResidual && residual <= kFieldMaxResidual) {
        code.Put(residual + kFieldMaxResidual, &writer);
      } else {
        code.Put(kFieldEscape, &writer);
        writer.Put(static_cast<uint64_t>(value), 8);
      }
    }
  }
  writer.Flush();
}

Status DecodeCoarseField(std::span<const uint8_t> bytes,
                         std::span<uint8_t, CoarseGrid::kCells> field) {
  constexpr int kSide = CoarseGrid::kSide;
  const FieldPrefixCode& code = FieldCode();
  bits::BitReader reader(bytes);
  uint8_t* f = field.data();
  for (int y = 0; y < kSide; ++y) {
    uint8_t* row = f + y * kSide;
    const uint8_t* above = y > 0 ? row - kSide : nullptr;
    // Residuals outside 0..255 (possible only in a damaged code) are caught after the row.
    bool out_of_range = false;
    for (int x = 0; x < kSide; ++x) {
      const int symbol = code.Get(&reader);
      int value = 0;
      if (symbol == kFieldEscape) {
        value = static_cast<int>(reader.Get(8));
      } else {
        const int prediction = above == nullptr ? (x == 0 ? 0 : row[x - 1])
                               : x == 0         ? above[0]
                                        : std::clamp(row[x - 1] + above[x] - above[x - 1], 0, 255);
        value = prediction + symbol - kFieldMaxResidual;
        out_of_range |= value < 0 || value > 255;
      }
      row[x] = static_cast<uint8_t>(value);
    }
    if (reader.overrun()) {
      return Status(
          StatusCode::kTruncated,
          "field code: " + std::to_string(bytes.size()) + " bytes end in row " + std::to_string(y));
    }
    if (out_of_range) {
      return Status(StatusCode::kOutOfRange,
                    "field code: a cell of row " + std::to_string(y) + " decodes outside 0..255");
    }
  }
  const uint64_t used = (reader.consumed() + 7) / 8;
  if (used != bytes.size()) {
    return Status(StatusCode::kSizeMismatch,
                  "field code: " + std::to_string(bytes.size()) + " bytes, the field uses " +
                      std::to_string(used));
  }
  if (reader.consumed() % 8 != 0 && (bytes.back() >> (reader.consumed() % 8)) != 0) {
    return Status(StatusCode::kNonZeroReserved, "field code: padding bits are not zero");
  }
  return Status::Ok();
}

}  // namespace handdb
