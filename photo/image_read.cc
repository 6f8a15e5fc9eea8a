#include "photo/image_read.h"

#include <dlfcn.h>
#include <fcntl.h>
#include <unistd.h>

#include <cstring>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "base/atomic_file.h"
#include "base/image_decode.h"

namespace handdb {
namespace {

DecodeOptions OptionsFor(int imread_flags) {
  DecodeOptions o;
  switch (imread_flags) {
    case cv::IMREAD_UNCHANGED:
      o.mode = DecodeOptions::Mode::kUnchanged;
      break;
    case cv::IMREAD_GRAYSCALE:
      o.mode = DecodeOptions::Mode::kGrey;
      break;
    case cv::IMREAD_COLOR:
      o.mode = DecodeOptions::Mode::kColor;
      break;
    case cv::IMREAD_REDUCED_COLOR_2:
      o = {DecodeOptions::Mode::kColor, 2};
      break;
    case cv::IMREAD_REDUCED_COLOR_4:
      o = {DecodeOptions::Mode::kColor, 4};
      break;
    case cv::IMREAD_REDUCED_COLOR_8:
      o = {DecodeOptions::Mode::kColor, 8};
      break;
    default:
      THROW_CHECK_MSG(false, "ReadImage: unsupported imread flags " << imread_flags);
  }
  return o;
}

// PNM and BMP, rare inputs, are read by OpenCV's imgcodecs, which handdb does not link: it pulls
// ~120 shared libraries (GDAL, codecs of formats handdb never reads) into the start of every
// process, `handdb --help` included. It is loaded on the first PNM or BMP picture instead.
using ImreadFn = decltype(&cv::imread);

Result<ImreadFn> LoadImread() {
  static std::once_flag once;
  static ImreadFn imread = nullptr;
  static std::string error;
  std::call_once(once, [] {
    void* lib = ::dlopen(HANDDB_OPENCV_IMGCODECS_SONAME, RTLD_NOW | RTLD_LOCAL);
    if (lib != nullptr) {
      // cv::imread(const std::string&, int), as the C++ ABI names it (OpenCV 4).
      imread = reinterpret_cast<ImreadFn>(
          ::dlsym(lib, "_ZN2cv6imreadERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEEi"));
    }
    if (imread == nullptr) error = ::dlerror();
  });
  if (imread == nullptr) {
    return Status(StatusCode::kBadImage,
                  std::string("PNM and BMP pictures are read with OpenCV's imgcodecs (") +
                      HANDDB_OPENCV_IMGCODECS_SONAME + "), which cannot be loaded: " + error);
  }
  return imread;
}

// The file's first bytes, enough for SniffImageFormat.
Result<std::vector<uint8_t>> Head(const std::filesystem::path& path) {
  if (Status s = CheckRegularFile(path); !s.ok()) return s;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    return Status(StatusCode::kIoError, path.string() + ": cannot open: " + std::strerror(errno));
  }
  std::vector<uint8_t> head(16);
  const ssize_t n = ::pread(fd, head.data(), head.size(), 0);
  ::close(fd);
  head.resize(n > 0 ? static_cast<size_t>(n) : 0);
  return head;
}

}  // namespace

Result<cv::Mat> ReadImage(const std::filesystem::path& path, int imread_flags) {
  const DecodeOptions options = OptionsFor(imread_flags);
  Result<std::vector<uint8_t>> head = Head(path);
  if (!head.ok()) return head.status();
  const ImageFormat format = SniffImageFormat(*head);
  if (format == ImageFormat::kPnm || format == ImageFormat::kBmp) {
    Result<ImreadFn> imread = LoadImread();
    if (!imread.ok())
      return Status(StatusCode::kBadImage, path.string() + ": " + imread.status().message());
    cv::Mat m = (*imread)(path.string(), imread_flags);
    if (m.empty()) {
      return Status(
          StatusCode::kBadImage,
          path.string() + ": cannot read the " + ImageFormatName(format) + " image (corrupt?)");
    }
    return m;
  }
  if (format == ImageFormat::kUnknown) {
    return Status(StatusCode::kBadImage,
                  path.string() + ": not a PNG, JPEG, PNM or BMP image (the formats read)");
  }
  DecodeOptions decode = options;
  if (format != ImageFormat::kJpeg) decode.reduce = 1;
  Result<DecodedImage> decoded = DecodeImageFile(path, decode);
  if (!decoded.ok()) return decoded.status();
  const int depth = decoded->bytes_per_sample == 2 ? CV_16U : CV_8U;
  cv::Mat m(decoded->height, decoded->width, CV_MAKETYPE(depth, decoded->channels));
  THROW_CHECK_EQ(m.step[0], decoded->row_bytes());
  std::memcpy(m.data, decoded->pixels.data(), decoded->pixels.size());
  // imread reduces what its decoder cannot (all but JPEG) by resizing the whole picture.
  if (options.reduce > 1 && format != ImageFormat::kJpeg) {
    cv::resize(m,
               m,
               cv::Size(m.cols / options.reduce, m.rows / options.reduce),
               0,
               0,
               cv::INTER_LINEAR_EXACT);
  }
  return m;
}

}  // namespace handdb
