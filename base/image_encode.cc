#include "base/image_encode.h"

#include <png.h>
#include <zlib.h>

#include <csetjmp>
#include <cstdio>
#include <string>

namespace handdb {
namespace {

struct PngEncodeSink {
  std::vector<uint8_t>* bytes = nullptr;
  char message[256] = {};
};

[[noreturn]] void PngEncodeError(png_structp png, png_const_charp message) {
  auto* sink = static_cast<PngEncodeSink*>(png_get_error_ptr(png));
  std::snprintf(sink->message, sizeof sink->message, "%s", message);
  png_longjmp(png, 1);
}

void PngEncodeWarning(png_structp, png_const_charp) {}

void PngEncodeWrite(png_structp png, png_bytep data, size_t size) {
  auto* sink = static_cast<PngEncodeSink*>(png_get_io_ptr(png));
  sink->bytes->insert(sink->bytes->end(), data, data + size);
}

void PngEncodeFlush(png_structp) {}

// OpenCV 4.6's PngEncoder::write with no parameters, call for call.
bool EncodeInto(const PngPixels& image, png_structp png, png_infop info, PngEncodeSink* sink) {
  if (setjmp(png_jmpbuf(png)) != 0) return false;
  std::vector<png_bytep> rows(static_cast<size_t>(image.height));
  for (int y = 0; y < image.height; ++y) {
    rows[static_cast<size_t>(y)] =
        const_cast<png_bytep>(image.data + image.row_bytes * static_cast<size_t>(y));
  }
  png_set_write_fn(png, sink, PngEncodeWrite, PngEncodeFlush);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
  png_set_compression_level(png, Z_BEST_SPEED);
  png_set_compression_strategy(png, Z_RLE);
  png_set_IHDR(png,
               info,
               static_cast<png_uint_32>(image.width),
               static_cast<png_uint_32>(image.height),
               8,
               image.channels == 1   ? PNG_COLOR_TYPE_GRAY
               : image.channels == 3 ? PNG_COLOR_TYPE_RGB
                                     : PNG_COLOR_TYPE_RGBA,
               PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_set_bgr(png);
  png_write_image(png, rows.data());
  png_write_end(png, info);
  return true;
}

}  // namespace

Result<std::vector<uint8_t>> EncodePng(const PngPixels& image) {
  if (image.data == nullptr || image.width <= 0 || image.height <= 0) {
    return Status(StatusCode::kInvalidArgument, "EncodePng: an empty image");
  }
  if (image.channels != 1 && image.channels != 3 && image.channels != 4) {
    return Status(StatusCode::kInvalidArgument,
                  "EncodePng: " + std::to_string(image.channels) + " channels (1, 3 or 4 encode)");
  }
  if (image.row_bytes < static_cast<size_t>(image.width) * static_cast<size_t>(image.channels)) {
    return Status(StatusCode::kInvalidArgument, "EncodePng: rows shorter than the width");
  }
  std::vector<uint8_t> bytes;
  PngEncodeSink sink;
  sink.bytes = &bytes;
  png_structp png =
      png_create_write_struct(PNG_LIBPNG_VER_STRING, &sink, PngEncodeError, PngEncodeWarning);
  if (png == nullptr) return Status(StatusCode::kIoError, "cannot start the PNG encoder");
  png_infop info = png_create_info_struct(png);
  const bool ok = info != nullptr && EncodeInto(image, png, info, &sink);
  png_destroy_write_struct(&png, &info);
  if (!ok) return Status(StatusCode::kIoError, std::string("PNG encoder: ") + sink.message);
  return bytes;
}

}  // namespace handdb
