// PNG and JPEG pictures decoded with the codecs' own libraries (libpng, libjpeg-turbo), into
// 8-bit (or, for a 16-bit PNG read unchanged, 16-bit) grey / BGR / BGRA pixels without OpenCV
// types.
//
// The pixels are those cv::imread returns for the same file and the matching flag (OpenCV decodes
// with the same libraries and the same transforms: libpng's strip/expand/bgr/rgb-to-grey
// settings, libjpeg's default islow DCT and fancy upsampling into JCS_EXT_BGR / JCS_GRAYSCALE,
// EXIF orientation applied to a JPEG except in kUnchanged), so callers wrap them in a cv::Mat
// header and see no difference. What differs is what happens to a damaged file: every libjpeg
// warning ("Corrupt JPEG data: ...", "Premature end of JPEG file") and every libpng error (a bad
// CRC, filter byte or zlib stream, an IHDR that lies) is a kBadImage naming the file, and nothing
// is printed to stderr (libpng's warnings about ancillary chunks are benign and stay silent).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "base/image_file.h"
#include "base/status.h"

namespace handdb {

enum class ImageFormat { kUnknown, kPng, kJpeg, kPnm, kBmp };

// The format by the file's first bytes (PNG and JPEG signatures, PNM "P1".."P6" + space, "BM").
ImageFormat SniffImageFormat(std::span<const uint8_t> head);
const char* ImageFormatName(ImageFormat format);  // "PNG", "JPEG", "PNM", "BMP", "unknown"

struct DecodeOptions {
  // As cv::imread's IMREAD_UNCHANGED, IMREAD_GRAYSCALE and IMREAD_COLOR.
  enum class Mode { kUnchanged, kGrey, kColor };
  Mode mode = Mode::kUnchanged;
  // 1, 2, 4 or 8: a JPEG decoded at 1/reduce of its size (IMREAD_REDUCED_COLOR_<reduce> with
  // mode kColor). PNGs are always decoded whole.
  int reduce = 1;
  // Pixels (of the decoded size) allowed before anything is allocated.
  uint64_t max_pixels = kMaxImagePixels;
  bool Check() const;
};

struct DecodedImage {
  int width = 0;
  int height = 0;
  int channels = 0;             // 1 grey, 3 BGR, 4 BGRA
  int bytes_per_sample = 1;     // 2 only for a 16-bit PNG in kUnchanged (native byte order)
  std::vector<uint8_t> pixels;  // rows without padding, top row first
  size_t row_bytes() const {
    return static_cast<size_t>(width) * static_cast<size_t>(channels) *
           static_cast<size_t>(bytes_per_sample);
  }
};

// Decodes a PNG or JPEG held in memory; `name` names it in errors. kBadImage "<name>: corrupt
// JPEG: <libjpeg's message>", "<name>: corrupt PNG: <libpng's message>", "<name>: W x H pixels
// (PNG), more than the N (64 Mpx) allowed", "<name>: not a PNG or JPEG image".
Result<DecodedImage> DecodeImage(std::span<const uint8_t> bytes,
                                 const std::string& name,
                                 const DecodeOptions& options = {});

// The same for a file (CheckRegularFile first; files above 1 GiB are refused unread).
Result<DecodedImage> DecodeImageFile(const std::filesystem::path& path,
                                     const DecodeOptions& options = {});

}  // namespace handdb
