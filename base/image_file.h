// Cheap checks on an image file's bytes before a decoder sees them: libjpeg and libpng decode a
// truncated file with only a warning on stderr (and grey or black rows where the data stopped), so
// a cut-off download would be searched as if it were the whole image.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>

#include "base/status.h"

namespace handdb {

// Pixels (width x height) an image may have before it is decoded: 64 Mpx (8192 x 8192; a 50 Mpx
// phone photo fits). A decoded image costs ~15 bytes per pixel through the query pipeline, so a
// 20000 x 20000 PNG of 5 MB would peak at 6.1 GB; at the limit it is ~1 GB.
constexpr uint64_t kMaxImagePixels = uint64_t{1} << 26;
// A JPEG can be decoded at 1/2, 1/4 or 1/8 of its size without ever holding the full image, so
// callers that do that may accept JPEGs up to 64x kMaxImagePixels (a 65536 x 65536 picture).
constexpr uint64_t kMaxJpegPixels = kMaxImagePixels * 64;

// Width and height from an image file's header, without decoding: PNG (IHDR), JPEG (the first
// SOFn marker), PNM (P1-P6) and BMP. nullopt for other formats or a header that does not parse.
struct ImageSize {
  uint64_t width = 0;
  uint64_t height = 0;
  const char* format = "";  // "PNG", "JPEG", "PNM", "BMP"
};
std::optional<ImageSize> ReadImageSize(const std::filesystem::path& path);

// Checks before a decoder sees the file. A regular file (CheckRegularFile); for a JPEG (FF D8 FF)
// or PNG (89 'PNG' ...) by content, complete: the JPEG's end-of-image marker (FF D9) or the PNG's
// IEND chunk is within its last 4 KiB (decoders allow trailing bytes); and, where ReadImageSize
// can read the header, at most kMaxImagePixels. Other formats are left to the decoder (OpenCV
// refuses above its own 2^30 pixels).
// kBadImage "<file>: truncated JPEG (no end-of-image marker)" / "... PNG (no IEND chunk)" /
// "<file>: 20000 x 20000 pixels (PNG header), more than the 67108864 (64 Mpx) allowed".
// `max_jpeg_pixels` is the limit for JPEGs (a caller that decodes them reduced may allow more).
Status CheckImageFileComplete(const std::filesystem::path& path,
                              uint64_t max_pixels = kMaxImagePixels,
                              uint64_t max_jpeg_pixels = kMaxImagePixels);

}  // namespace handdb
