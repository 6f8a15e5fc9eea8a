// Lossless compression of a view's coarse field (format/coarse_field.h;
// docs/format.md section 10, "Compressed points and coarse fields").
//
// A field is 43 x 43 bytes of distances that change by at most 16 units (one 8 px cell) from a
// cell to the next, and are close to planar away from the points. Each cell is predicted from
// its west, north and north-west neighbours (W + N - NW, clamped to 0..255; W on the first row,
// N in the first column, 0 for the first cell) and the residual, -15..15, coded by a fixed
// canonical Huffman code (lengths from the residuals of the paper database's fields:
// bench/point_codec_bench); other residuals by an escape and the cell's 8 bits. Least
// significant bit first, zero-padded to a byte. About 2.6 bits per cell, ~600 bytes per field
// instead of 1,849.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "base/status.h"
#include "format/coarse_field.h"

namespace handdb {

// Appends the code of `field` (CoarseGrid::kCells bytes, row-major) to *out.
void EncodeCoarseField(std::span<const uint8_t, CoarseGrid::kCells> field, std::string* out);

// Decodes a whole code made by EncodeCoarseField into `field`. kTruncated when the code ends
// early, kSizeMismatch when bytes are left over, kNonZeroReserved for non-zero padding bits.
Status DecodeCoarseField(std::span<const uint8_t> code,
                         std::span<uint8_t, CoarseGrid::kCells> field);

}  // namespace handdb
