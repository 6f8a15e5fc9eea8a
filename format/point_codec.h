// Lossless compression of a view's edge points on the source pixel lattice (format v1.2;
// docs/format.md section 10, "Compressed points and coarse fields").
//
// A converted view's points are its edge pixels (integer columns and rows of the rendered label
// image) pushed through the normalisation (edges/normalise.h): PointQ = round((pixel centre -
// centre) * scale * 16). Stored as PointQ they take 4 bytes each (~2,400 bytes per view), but the
// pixels themselves form thin curves, which a chain code stores in about 2 bits per pixel: the
// pixels are walked as chains of 8-neighbour moves, each move coded by a fixed prefix code
// (canonical Huffman, lengths from moves measured on rendered databases) given whether the
// previous move was axial or diagonal; each chain's start is coded relative to the previous
// start in raster order (Elias gamma). Decoding rebuilds the pixel set in raster order (row,
// then column), which is also the order NormalisePixels sorts the points into.
//
// Stream (bytes): varint n (pixels); when n > 0: zigzag varints min column, min row, varints
// width - 1, height - 1 of the pixels' bounding box, then a bit stream (least significant bit
// first) of the chains, zero-padded to a byte. Every pixel is coded exactly once, so n and the
// stream must agree: a decoder that finds a move off the box, onto a pixel already coded, or
// bytes left over rejects the stream.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/view.h"

namespace handdb {

struct LatticePixel {
  int32_t col = 0;
  int32_t row = 0;
  friend bool operator==(const LatticePixel&, const LatticePixel&) = default;
};

// Largest bounding box side the codec accepts: the largest render (schemas/config.schema.json,
// 8192 px). The encoder's work memory is one byte per box pixel, the decoder's one bit.
constexpr int32_t kMaxLatticeSide = 8192;

// Appends the code of `pixels` (any order; duplicates are coded once) to *out.
// kOutOfRange when their bounding box is wider or taller than kMaxLatticeSide.
Status EncodeLatticePixels(std::span<const LatticePixel> pixels, std::string* out);

// Decodes a whole stream made by EncodeLatticePixels into *out (replaced), in raster order.
// Errors (kTruncated, kOutOfRange, kSizeMismatch) say what is wrong and where (byte offset);
// the caller adds the file and view. Never reads outside `code`; memory is bounded by the box
// (at most kMaxLatticeSide^2 bits, 8 MB) and n.
Status DecodeLatticePixels(std::span<const uint8_t> code, std::vector<LatticePixel>* out);

// Statistics of a code, for benchmarks: chains and move bits.
struct LatticeCodeStats {
  uint64_t pixels = 0;
  uint64_t chains = 0;
  uint64_t start_bits = 0;  // chain starts
  uint64_t move_bits = 0;   // moves and chain ends
  uint64_t header_bytes = 0;
  // Moves by context (0: after an axial move or at a chain's start, 1: after a diagonal move)
  // and symbol (0-7: the move's direction relative to the previous move's, in 45-degree
  // steps clockwise on the image (y down): 0 straight on; 8: end of chain).
  uint64_t symbols[2][9] = {};
};
// Like EncodeLatticePixels, and adds what it coded to *stats.
Status EncodeLatticePixels(std::span<const LatticePixel> pixels,
                           std::string* out,
                           LatticeCodeStats* stats);

// A view's points (PointQ, in any order), coded exactly. The first byte says the mode.
// Mode 0, for points sorted by (y, x), unique and on the render's lattice (every converted view;
// not bench/synth_db's jittered copies, which are not even sorted): the pixels are recovered
// with the view's normalisation as its record keeps it (`scale`, `centre` = source_centre_px,
// float: pixel = round(point / (16 scale) + centre - 1/2)), chain-coded by EncodeLatticePixels
// (after a varint of its length), and the few points the pixels do not give back exactly (the
// converter normalised in double) follow as corrections: varint count, then per correction a
// varint index step (in raster order; the first is the index itself) and zigzag varints dx, dy.
// Mode 1, for anything else (points off the lattice, two points on one pixel, a degenerate scale,
// any order): varint count, then per point zigzag varint y step and, on the same row, zigzag
// varint x step, else zigzag varint x. The encoder decodes its own mode-0 code and falls back to
// mode 1 unless it gives the points back exactly, and uses mode 1 when that is no longer, so
// decoding always returns the input. *mode: which was used.
Status EncodeViewPoints(std::span<const PointQ> points,
                        float scale,
                        std::array<float, 2> centre,
                        std::string* out,
                        int* mode = nullptr);

// The inverse (the same scale and centre). Errors name what is wrong; a mode-0 result is checked
// to be sorted by (y, x) and unique, and its corrections to move a point by at most 1/16 px in
// x and y.
Status DecodeViewPoints(std::span<const uint8_t> code,
                        float scale,
                        std::array<float, 2> centre,
                        std::vector<PointQ>* out);

// What a view's code says about its points without decoding them (a few bytes of its header):
// for a lattice-mode code (mode 0) peeked is true, count is the number of points, sorted is true
// (a mode-0 decode is sorted by (y, x) or an error) and max_abs_bound bounds every decoded
// point's |x| and |y| (the decoder keeps every pixel inside the code's bounding box and every
// correction within 1/16 px). For a mode-1 code peeked is false: only decoding tells. A header
// that cannot be read is an error; the rest of the code is not checked (DecodeViewPoints does).
struct ViewPointsExtent {
  bool peeked = false;
  uint64_t count = 0;
  int32_t max_abs_bound = 0;
  bool sorted = false;
};
Status PeekViewPoints(std::span<const uint8_t> code,
                      float scale,
                      std::array<float, 2> centre,
                      ViewPointsExtent* out);

}  // namespace handdb
