// PNG pictures encoded with libpng itself, from 8-bit grey / BGR / BGRA rows without OpenCV
// types: the bytes cv::imencode(".png", ...) writes for the same pixels and default parameters
// (the same libpng and zlib calls: the Sub filter, zlib's fastest level, the RLE strategy), so
// a contact sheet, a plot or `handdb show` writes the same file as before, and the `handdb`
// binary need not load OpenCV's imgcodecs (and the ~120 libraries it pulls in) to write one.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "base/status.h"

namespace handdb {

struct PngPixels {
  const uint8_t* data = nullptr;  // top row first
  int width = 0;
  int height = 0;
  int channels = 0;      // 1 grey, 3 BGR, 4 BGRA
  size_t row_bytes = 0;  // >= width * channels
};

// kInvalidArgument for an empty image, a channel count other than 1, 3 or 4 or rows shorter
// than width * channels; kIoError when libpng fails.
Result<std::vector<uint8_t>> EncodePng(const PngPixels& image);

}  // namespace handdb
