#include "base/image_decode.h"

// clang-format off
#include <cstdio>  // jpeglib.h needs FILE and size_t declared first
#include <jpeglib.h>
// clang-format on
#include <png.h>

#include <algorithm>
#include <csetjmp>
#include <cstring>
#include <string_view>
#include <utility>

#include "base/atomic_file.h"

namespace handdb {
namespace {

constexpr uint64_t kMaxImageFileBytes = uint64_t{1} << 30;

Status Bad(const std::string& name, const std::string& problem) {
  return Status(StatusCode::kBadImage, name + ": " + problem);
}

Status TooManyPixels(
    const std::string& name, uint64_t width, uint64_t height, const char* format, uint64_t limit) {
  return Bad(name,
             std::to_string(width) + " x " + std::to_string(height) + " pixels (" + format +
                 "), more than the " + std::to_string(limit) + " (" + std::to_string(limit >> 20) +
                 " Mpx) allowed");
}

// ---- EXIF orientation (JPEG) -------------------------------------------------------------------

// The orientation tag (0x0112) of IFD0 in an APP1 segment's TIFF block, read as OpenCV's
// ExifReader reads it (the first APP1 segment, the TIFF header 6 bytes in); 1 (as stored) when
// absent or malformed.
int ExifOrientation(std::span<const uint8_t> app1) {
  if (app1.size() <= 6) return 1;
  const std::span<const uint8_t> tiff = app1.subspan(6);
  if (tiff.size() < 8) return 1;
  bool little;
  if (tiff[0] == 'I' && tiff[1] == 'I') {
    little = true;
  } else if (tiff[0] == 'M' && tiff[1] == 'M') {
    little = false;
  } else {
    return 1;
  }
  auto u16 = [&](size_t at) -> uint32_t {
    return little ? tiff[at] | (tiff[at + 1] << 8) : (tiff[at] << 8) | tiff[at + 1];
  };
  auto u32 = [&](size_t at) -> uint32_t {
    return little ? u16(at) | (u16(at + 2) << 16) : (u16(at) << 16) | u16(at + 2);
  };
  if (u16(2) != 0x2A) return 1;
  const uint64_t ifd = u32(4);
  if (ifd + 2 > tiff.size()) return 1;
  const uint32_t entries = u16(ifd);
  for (uint32_t i = 0; i < entries; ++i) {
    const uint64_t at = ifd + 2 + 12 * uint64_t{i};
    if (at + 12 > tiff.size()) return 1;
    if (u16(at) == 0x0112) return static_cast<int>(u16(at + 8));
  }
  return 1;
}

// cv::flip / cv::transpose as OpenCV's ApplyExifOrientation composes them for orientations 2-8.
void ApplyOrientation(int orientation, DecodedImage* img) {
  if (orientation < 2 || orientation > 8) return;
  const bool transpose = orientation >= 5;
  bool flip_x = false, flip_y = false;  // applied after the transpose
  switch (orientation) {
    case 2:
      flip_x = true;
      break;
    case 3:
      flip_x = flip_y = true;
      break;
    case 4:
      flip_y = true;
      break;
    case 6:
      flip_x = true;
      break;
    case 7:
      flip_x = flip_y = true;
      break;
    case 8:
      flip_y = true;
      break;
    default:
      break;
  }
  const int w = img->width, h = img->height;
  const int out_w = transpose ? h : w, out_h = transpose ? w : h;
  const size_t px = static_cast<size_t>(img->channels) * static_cast<size_t>(img->bytes_per_sample);
  std::vector<uint8_t> out(img->pixels.size());
  for (int y = 0; y < out_h; ++y) {
    for (int x = 0; x < out_w; ++x) {
      const int tx = flip_x ? out_w - 1 - x : x;  // position before the flips
      const int ty = flip_y ? out_h - 1 - y : y;
      const int sx = transpose ? ty : tx, sy = transpose ? tx : ty;
      std::memcpy(out.data() + (static_cast<size_t>(y) * out_w + x) * px,
                  img->pixels.data() + (static_cast<size_t>(sy) * w + sx) * px,
                  px);
    }
  }
  img->pixels = std::move(out);
  img->width = out_w;
  img->height = out_h;
}

// ---- JPEG --------------------------------------------------------------------------------------

struct JpegError {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

[[noreturn]] void JpegErrorExit(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<JpegError*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  std::longjmp(err->jump, 1);
}

// Warnings (level -1) mean damaged data that libjpeg would decode as grey blocks: refused like
// errors. Trace messages (level >= 0) are dropped. Nothing is printed.
void JpegEmitMessage(j_common_ptr cinfo, int level) {
  if (level < 0) JpegErrorExit(cinfo);
}

// OpenCV's icvCvt_CMYK2BGR_8u_C4C3R and icvCvt_CMYK2Gray_8u_C4C1R.
void CmykToBgr(const uint8_t* cmyk, uint8_t* bgr, int width) {
  for (int i = 0; i < width; ++i, cmyk += 4, bgr += 3) {
    const int k = cmyk[3];
    const int c = k - ((255 - cmyk[0]) * k >> 8);
    const int m = k - ((255 - cmyk[1]) * k >> 8);
    const int y = k - ((255 - cmyk[2]) * k >> 8);
    bgr[2] = static_cast<uint8_t>(c);
    bgr[1] = static_cast<uint8_t>(m);
    bgr[0] = static_cast<uint8_t>(y);
  }
}

void CmykToGrey(const uint8_t* cmyk, uint8_t* grey, int width) {
  constexpr int kShift = 14, kR = 4899, kG = 9617, kB = 1868;
  for (int i = 0; i < width; ++i, cmyk += 4) {
    const int k = cmyk[3];
    const int c = k - ((255 - cmyk[0]) * k >> 8);
    const int m = k - ((255 - cmyk[1]) * k >> 8);
    const int y = k - ((255 - cmyk[2]) * k >> 8);
    grey[i] = static_cast<uint8_t>((y * kB + m * kG + c * kR + (1 << (kShift - 1))) >> kShift);
  }
}

struct JpegState {
  jpeg_decompress_struct cinfo;
  JpegError err;
  std::vector<uint8_t> cmyk_row;
};

// The libjpeg calls, in OpenCV's JpegDecoder order (readHeader, then readData). Returns false
// with state->err.message set; no C++ object with a destructor lives in this frame.
bool DecodeJpegInto(std::span<const uint8_t> bytes,
                    const DecodeOptions& options,
                    JpegState* state,
                    DecodedImage* out,
                    std::string* too_big) {
  jpeg_decompress_struct* cinfo = &state->cinfo;
  cinfo->err = jpeg_std_error(&state->err.mgr);
  state->err.mgr.error_exit = JpegErrorExit;
  state->err.mgr.emit_message = JpegEmitMessage;
  if (setjmp(state->err.jump) != 0) return false;
  jpeg_create_decompress(cinfo);
  jpeg_mem_src(cinfo, bytes.data(), static_cast<unsigned long>(bytes.size()));
  jpeg_save_markers(cinfo, JPEG_APP0 + 1, 0xffff);
  jpeg_read_header(cinfo, TRUE);
  cinfo->scale_num = 1;
  cinfo->scale_denom = static_cast<unsigned int>(options.reduce);
  jpeg_calc_output_dimensions(cinfo);
  const uint64_t pixels = uint64_t{cinfo->output_width} * cinfo->output_height;
  if (pixels > options.max_pixels || pixels == 0) {
    *too_big = std::to_string(cinfo->output_width) + "x" + std::to_string(cinfo->output_height);
    return false;
  }
  // The decoder's own type (3 channels when the file has more than one), then imread's flags.
  const bool file_colour = cinfo->num_components > 1;
  const bool colour = options.mode == DecodeOptions::Mode::kColor ||
                      (options.mode == DecodeOptions::Mode::kUnchanged && file_colour);
  const bool cmyk = cinfo->num_components == 4;
  if (colour) {
    cinfo->out_color_space = cmyk ? JCS_CMYK : JCS_EXT_BGR;
    cinfo->out_color_components = cmyk ? 4 : 3;
  } else {
    cinfo->out_color_space = cmyk ? JCS_CMYK : JCS_GRAYSCALE;
    cinfo->out_color_components = cmyk ? 4 : 1;
  }
  int orientation = 1;
  for (jpeg_saved_marker_ptr m = cinfo->marker_list; m != nullptr; m = m->next) {
    if (m->marker == JPEG_APP0 + 1) {
      orientation = ExifOrientation({m->data, m->data_length});
      break;
    }
  }
  jpeg_start_decompress(cinfo);
  out->width = static_cast<int>(cinfo->output_width);
  out->height = static_cast<int>(cinfo->output_height);
  out->channels = colour ? 3 : 1;
  out->bytes_per_sample = 1;
  out->pixels.resize(out->row_bytes() * static_cast<size_t>(out->height));
  if (cmyk) state->cmyk_row.resize(static_cast<size_t>(out->width) * 4);
  while (cinfo->output_scanline < cinfo->output_height) {
    uint8_t* row = out->pixels.data() + out->row_bytes() * cinfo->output_scanline;
    JSAMPROW target = cmyk ? state->cmyk_row.data() : row;
    jpeg_read_scanlines(cinfo, &target, 1);
    if (cmyk) {
      if (colour) {
        CmykToBgr(state->cmyk_row.data(), row, out->width);
      } else {
        CmykToGrey(state->cmyk_row.data(), row, out->width);
      }
    }
  }
  jpeg_finish_decompress(cinfo);
  if (options.mode != DecodeOptions::Mode::kUnchanged) ApplyOrientation(orientation, out);
  return true;
}

Result<DecodedImage> DecodeJpeg(std::span<const uint8_t> bytes,
                                const std::string& name,
                                const DecodeOptions& options) {
  JpegState state{};
  DecodedImage out;
  std::string too_big;
  const bool ok = DecodeJpegInto(bytes, options, &state, &out, &too_big);
  const std::string message = state.err.message;
  jpeg_destroy_decompress(&state.cinfo);
  if (!too_big.empty()) {
    const size_t x = too_big.find('x');
    return TooManyPixels(name,
                         std::stoull(too_big.substr(0, x)),
                         std::stoull(too_big.substr(x + 1)),
                         "JPEG",
                         options.max_pixels);
  }
  if (!ok) return Bad(name, "corrupt JPEG: " + message);
  return out;
}

// ---- PNG ---------------------------------------------------------------------------------------

struct PngSource {
  std::span<const uint8_t> bytes;
  size_t at = 0;
  char message[256] = {};
};

[[noreturn]] void PngError(png_structp png, png_const_charp message) {
  auto* src = static_cast<PngSource*>(png_get_error_ptr(png));
  std::snprintf(src->message, sizeof src->message, "%s", message);
  png_longjmp(png, 1);
}

// Benign problems (an ancillary chunk's CRC, an sRGB profile libpng knows to be wrong, extra
// data after the image) leave the pixels whole: decoded as OpenCV decodes them, without the
// message libpng would print.
void PngWarning(png_structp, png_const_charp) {}

void PngRead(png_structp png, png_bytep data, size_t size) {
  auto* src = static_cast<PngSource*>(png_get_io_ptr(png));
  if (size > src->bytes.size() - src->at) png_error(png, "the file ends inside a chunk");
  std::memcpy(data, src->bytes.data() + src->at, size);
  src->at += size;
}

struct PngState {
  png_structp png = nullptr;
  png_infop info = nullptr;
  png_infop end = nullptr;
  PngSource src;
  std::vector<png_bytep> rows;
};

// The libpng calls of OpenCV's PngDecoder (readHeader, then readData) for imread's flags.
bool DecodePngInto(const DecodeOptions& options,
                   PngState* s,
                   DecodedImage* out,
                   std::string* too_big) {
  if (setjmp(png_jmpbuf(s->png)) != 0) return false;
  png_set_read_fn(s->png, &s->src, PngRead);
  png_read_info(s->png, s->info);
  png_uint_32 width = 0, height = 0;
  int bit_depth = 0, color_type = 0;
  png_get_IHDR(
      s->png, s->info, &width, &height, &bit_depth, &color_type, nullptr, nullptr, nullptr);
  const uint64_t pixels = uint64_t{width} * height;
  if (pixels > options.max_pixels || pixels == 0) {
    *too_big = std::to_string(width) + "x" + std::to_string(height);
    return false;
  }
  // The decoder's type (PngDecoder::readHeader).
  int channels = 1;
  if (color_type == PNG_COLOR_TYPE_RGB || color_type == PNG_COLOR_TYPE_PALETTE) {
    png_bytep trans = nullptr;
    int num_trans = 0;
    png_color_16p trans_values = nullptr;
    png_get_tRNS(s->png, s->info, &trans, &num_trans, &trans_values);
    channels = num_trans > 0 ? 4 : 3;
  } else if (color_type == PNG_COLOR_TYPE_GRAY_ALPHA || color_type == PNG_COLOR_TYPE_RGB_ALPHA) {
    channels = 4;
  }
  int bytes_per_sample = bit_depth == 16 ? 2 : 1;
  // imread's flags (loadsave.cpp): anything but IMREAD_UNCHANGED is 8-bit, 3 or 1 channels.
  if (options.mode != DecodeOptions::Mode::kUnchanged) {
    bytes_per_sample = 1;
    channels = options.mode == DecodeOptions::Mode::kColor ? 3 : 1;
  }
  const bool colour = channels > 1;
  // PngDecoder::readData.
  if (bytes_per_sample == 1 && bit_depth == 16) {
    png_set_strip_16(s->png);
  } else {
    png_set_swap(s->png);  // 16-bit samples in the machine's (little-endian) order
  }
  if (channels < 4) {
    png_set_strip_alpha(s->png);
  } else {
    png_set_tRNS_to_alpha(s->png);
  }
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(s->png);
  if ((color_type & PNG_COLOR_MASK_COLOR) == 0 && bit_depth < 8) {
    png_set_expand_gray_1_2_4_to_8(s->png);
  }
  if ((color_type & PNG_COLOR_MASK_COLOR) && colour) {
    png_set_bgr(s->png);
  } else if (colour) {
    png_set_gray_to_rgb(s->png);
  } else {
    png_set_rgb_to_gray(s->png, 1, 0.299, 0.587);
  }
  png_set_interlace_handling(s->png);
  png_read_update_info(s->png, s->info);
  out->width = static_cast<int>(width);
  out->height = static_cast<int>(height);
  out->channels = channels;
  out->bytes_per_sample = bytes_per_sample;
  if (png_get_rowbytes(s->png, s->info) != out->row_bytes()) {
    png_error(s->png, "unexpected row size after the colour transforms");
  }
  out->pixels.resize(out->row_bytes() * height);
  s->rows.resize(height);
  for (png_uint_32 y = 0; y < height; ++y) s->rows[y] = out->pixels.data() + out->row_bytes() * y;
  png_read_image(s->png, s->rows.data());
  png_read_end(s->png, s->end);
  return true;
}

Result<DecodedImage> DecodePng(std::span<const uint8_t> bytes,
                               const std::string& name,
                               const DecodeOptions& options) {
  PngState s;
  s.src.bytes = bytes;
  s.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &s.src, PngError, PngWarning);
  if (s.png == nullptr) return Bad(name, "cannot start the PNG decoder");
  s.info = png_create_info_struct(s.png);
  s.end = png_create_info_struct(s.png);
  DecodedImage out;
  std::string too_big;
  bool ok = s.info != nullptr && s.end != nullptr;
  if (ok) ok = DecodePngInto(options, &s, &out, &too_big);
  png_destroy_read_struct(&s.png, &s.info, &s.end);
  if (!too_big.empty()) {
    const size_t x = too_big.find('x');
    return TooManyPixels(name,
                         std::stoull(too_big.substr(0, x)),
                         std::stoull(too_big.substr(x + 1)),
                         "PNG",
                         options.max_pixels);
  }
  if (!ok) return Bad(name, std::string("corrupt PNG: ") + s.src.message);
  return out;
}

}  // namespace

ImageFormat SniffImageFormat(std::span<const uint8_t> head) {
  const std::string_view h(reinterpret_cast<const char*>(head.data()), head.size());
  if (h.size() >= 8 && h.substr(0, 8) == std::string_view("\x89PNG\r\n\x1A\n", 8)) {
    return ImageFormat::kPng;
  }
  if (h.size() >= 3 && h.substr(0, 3) == std::string_view("\xFF\xD8\xFF", 3)) {
    return ImageFormat::kJpeg;
  }
  if (h.size() >= 3 && h[0] == 'P' && h[1] >= '1' && h[1] <= '6' &&
      (h[2] == ' ' || h[2] == '\t' || h[2] == '\n' || h[2] == '\r')) {
    return ImageFormat::kPnm;
  }
  if (h.size() >= 2 && h.substr(0, 2) == "BM") return ImageFormat::kBmp;
  return ImageFormat::kUnknown;
}

const char* ImageFormatName(ImageFormat format) {
  switch (format) {
    case ImageFormat::kPng:
      return "PNG";
    case ImageFormat::kJpeg:
      return "JPEG";
    case ImageFormat::kPnm:
      return "PNM";
    case ImageFormat::kBmp:
      return "BMP";
    case ImageFormat::kUnknown:
      break;
  }
  return "unknown";
}

bool DecodeOptions::Check() const {
  CHECK_OPTION(reduce == 1 || reduce == 2 || reduce == 4 || reduce == 8);
  CHECK_OPTION(reduce == 1 || mode == Mode::kColor);
  CHECK_OPTION_GT(max_pixels, 0u);
  return true;
}

Result<DecodedImage> DecodeImage(std::span<const uint8_t> bytes,
                                 const std::string& name,
                                 const DecodeOptions& options) {
  THROW_CHECK(options.Check());
  switch (SniffImageFormat(bytes)) {
    case ImageFormat::kPng:
      return DecodePng(bytes, name, options);
    case ImageFormat::kJpeg:
      return DecodeJpeg(bytes, name, options);
    default:
      return Bad(name, "not a PNG or JPEG image");
  }
}

Result<DecodedImage> DecodeImageFile(const std::filesystem::path& path,
                                     const DecodeOptions& options) {
  Result<std::string> bytes = ReadFileToString(path, kMaxImageFileBytes);
  if (!bytes.ok()) return bytes.status();
  return DecodeImage(
      {reinterpret_cast<const uint8_t*>(bytes->data()), bytes->size()}, path.string(), options);
}

}  // namespace handdb
