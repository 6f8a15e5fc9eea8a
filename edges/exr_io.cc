#include "edges/exr_io.h"

#include <Imath/half.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIO.h>
#include <OpenEXR/ImfInputPart.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfTestFile.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <fstream>
#include <memory>
#include <sstream>
#include <system_error>
#include <vector>

#include "base/atomic_file.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// The largest resolution a render plan allows (schemas/render_plan.schema.json); a header
// claiming more is refused before any allocation.
constexpr int64_t kMaxExrSide = 8192;

std::string OneLine(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s.empty() ? "unknown error" : s;
}

Status Error(StatusCode code, const fs::path& path, const std::string& what) {
  return Status(code, path.string() + ": " + what);
}

// An OpenEXR output stream into memory: the file is encoded first, then written atomically.
class MemoryOStream : public Imf::OStream {
 public:
  MemoryOStream() : Imf::OStream("memory") {}
  void write(const char c[], int n) override {
    const size_t end = pos_ + static_cast<size_t>(n);
    if (end > bytes_.size()) bytes_.resize(end);
    std::memcpy(bytes_.data() + pos_, c, static_cast<size_t>(n));
    pos_ = end;
  }
  uint64_t tellp() override { return pos_; }
  void seekp(uint64_t pos) override { pos_ = static_cast<size_t>(pos); }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
  size_t pos_ = 0;
};

// The compression named as OIIO and Blender name it ("zip", "piz", "none", ...).
bool ParseCompression(const std::string& name, Imf::Compression* out) {
  static const std::pair<const char*, Imf::Compression> kNames[] = {
      {"none", Imf::NO_COMPRESSION},
      {"rle", Imf::RLE_COMPRESSION},
      {"zips", Imf::ZIPS_COMPRESSION},
      {"zip", Imf::ZIP_COMPRESSION},
      {"piz", Imf::PIZ_COMPRESSION},
      {"pxr24", Imf::PXR24_COMPRESSION},
      {"b44", Imf::B44_COMPRESSION},
      {"b44a", Imf::B44A_COMPRESSION},
      {"dwaa", Imf::DWAA_COMPRESSION},
      {"dwab", Imf::DWAB_COMPRESSION},
  };
  for (const auto& [n, c] : kNames) {
    if (name == n) {
      *out = c;
      return true;
    }
  }
  return false;
}

std::string FormatFloat(float v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

// What a file that is not an EXR looks like, from its first bytes, for the error message.
std::string SniffFormat(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char m[8] = {};
  in.read(reinterpret_cast<char*>(m), sizeof m);
  const auto n = in.gcount();
  if (n >= 8 && std::memcmp(m, "\x89PNG\r\n\x1a\n", 8) == 0) return "a PNG image";
  if (n >= 3 && m[0] == 0xFF && m[1] == 0xD8 && m[2] == 0xFF) return "a JPEG image";
  if (n >= 4 && (std::memcmp(m, "II*\0", 4) == 0 || std::memcmp(m, "MM\0*", 4) == 0)) {
    return "a TIFF image";
  }
  if (n >= 2 && m[0] == 'B' && m[1] == 'M') return "a BMP image";
  if (n == 0) return "an empty file";
  return "no EXR magic number";
}

}  // namespace

bool ExrReadOptions::Check() const {
  CHECK_OPTION_GE(expected_width, 0);
  CHECK_OPTION_GE(expected_height, 0);
  return true;
}

Result<LabelImage> ReadLabelExr(const fs::path& path, const ExrReadOptions& options) {
  THROW_CHECK(options.Check());
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) {
    return Error(StatusCode::kNotFound, path, "no such file");
  }
  if (!Imf::isOpenExrFile(path.c_str())) {
    return Error(StatusCode::kBadImage,
                 path,
                 "cannot read as an EXR image: not an OpenEXR file (" + SniffFormat(path) + ")");
  }
  // OpenEXR reports every problem by exception: an unreadable header is kBadImage, pixel data
  // that cannot be read kTruncated.
  std::unique_ptr<Imf::MultiPartInputFile> file;
  try {
    file = std::make_unique<Imf::MultiPartInputFile>(path.c_str());
  } catch (const std::exception& e) {
    return Error(StatusCode::kBadImage, path, "cannot read as an EXR image: " + OneLine(e.what()));
  }
  // Blender writes one part; look through every part in case a tool split the layers.
  int label_part = -1, depth_part = -1;
  std::string label_name, depth_name;
  std::vector<std::string> all_channels;
  for (int part = 0; part < file->parts(); ++part) {
    const Imf::ChannelList& channels = file->header(part).channels();
    for (auto it = channels.begin(); it != channels.end(); ++it) {
      const std::string name = it.name();
      all_channels.push_back(name);
      if (label_part < 0 && EndsWith(name, kLabelChannelSuffix)) {
        label_part = part;
        label_name = name;
      }
      if (depth_part < 0 && EndsWith(name, kDepthChannelSuffix)) {
        depth_part = part;
        depth_name = name;
      }
    }
  }
  auto channel_list = [&] {
    std::string s;
    for (const auto& c : all_channels) s += (s.empty() ? "" : ", ") + c;
    return s.empty() ? std::string("none") : s;
  };
  if (label_part < 0) {
    return Error(StatusCode::kBadImage,
                 path,
                 std::string("no label channel ending in '") + kLabelChannelSuffix +
                     "' (channels: " + channel_list() + ")");
  }
  if (options.require_depth && depth_part < 0) {
    return Error(StatusCode::kBadImage,
                 path,
                 std::string("no depth channel ending in '") + kDepthChannelSuffix +
                     "' (channels: " + channel_list() + ")");
  }

  LabelImage image;
  auto read_channel = [&](int part, const std::string& name, std::vector<float>* out) -> Status {
    const Imf::Header& header = file->header(part);
    const Imath::Box2i data = header.dataWindow();
    const Imath::Box2i display = header.displayWindow();
    const int64_t width = int64_t{data.max.x} - data.min.x + 1;
    const int64_t height = int64_t{data.max.y} - data.min.y + 1;
    const int64_t full_width = int64_t{display.max.x} - display.min.x + 1;
    const int64_t full_height = int64_t{display.max.y} - display.min.y + 1;
    if (data.min.x != 0 || data.min.y != 0 || width != full_width || height != full_height) {
      return Error(StatusCode::kSizeMismatch,
                   path,
                   "data window " + std::to_string(width) + "x" + std::to_string(height) + "+" +
                       std::to_string(data.min.x) + "+" + std::to_string(data.min.y) +
                       " is not the full display window " + std::to_string(full_width) + "x" +
                       std::to_string(full_height));
    }
    if ((options.expected_width > 0 && width != options.expected_width) ||
        (options.expected_height > 0 && height != options.expected_height)) {
      return Error(StatusCode::kSizeMismatch,
                   path,
                   "image is " + std::to_string(width) + "x" + std::to_string(height) +
                       ", expected " + std::to_string(options.expected_width) + "x" +
                       std::to_string(options.expected_height));
    }
    if (width <= 0 || height <= 0) {
      return Error(StatusCode::kSizeMismatch, path, "empty image");
    }
    if (width > kMaxExrSide || height > kMaxExrSide) {
      return Error(StatusCode::kSizeMismatch,
                   path,
                   "image is " + std::to_string(width) + "x" + std::to_string(height) +
                       ", larger than a label render can be (" + std::to_string(kMaxExrSide) +
                       " px per side)");
    }
    if (image.width == 0) {
      image.width = static_cast<int>(width);
      image.height = static_cast<int>(height);
    } else if (image.width != width || image.height != height) {
      return Error(StatusCode::kSizeMismatch, path, "label and depth parts differ in size");
    }
    const Imf::Channel& channel = header.channels()[name];
    if (channel.xSampling != 1 || channel.ySampling != 1) {
      return Error(StatusCode::kBadImage, path, "channel " + name + " is subsampled");
    }
    out->assign(static_cast<size_t>(width) * static_cast<size_t>(height), 0.0f);
    try {
      Imf::InputPart in(*file, part);
      Imf::FrameBuffer frame;
      frame.insert(name,
                   Imf::Slice(Imf::FLOAT,
                              reinterpret_cast<char*>(out->data()),
                              sizeof(float),
                              sizeof(float) * static_cast<size_t>(width)));
      in.setFrameBuffer(frame);
      in.readPixels(data.min.y, data.max.y);
    } catch (const std::exception& e) {
      return Error(StatusCode::kTruncated,
                   path,
                   "pixel data unreadable (truncated or corrupt): " + OneLine(e.what()));
    }
    return Status::Ok();
  };

  std::vector<float> label_values;
  HANDDB_RETURN_IF_ERROR(read_channel(label_part, label_name, &label_values));
  if (depth_part >= 0) HANDDB_RETURN_IF_ERROR(read_channel(depth_part, depth_name, &image.depth));

  image.labels.resize(label_values.size());
  for (size_t i = 0; i < label_values.size(); ++i) {
    const float v = label_values[i];
    if (!(v >= 0.0f && v <= static_cast<float>(kNumLinks)) || v != std::floor(v)) {
      const size_t col = i % static_cast<size_t>(image.width);
      const size_t row = i / static_cast<size_t>(image.width);
      return Error(StatusCode::kOutOfRange,
                   path,
                   "pixel (" + std::to_string(col) + ", " + std::to_string(row) + "): label " +
                       FormatFloat(v) + " is not an integer link id in 0.." +
                       std::to_string(kNumLinks));
    }
    image.labels[i] = static_cast<uint8_t>(v);
  }
  if (!image.depth.empty()) {
    for (size_t i = 0; i < image.depth.size(); ++i) {
      if (image.labels[i] != 0 && !std::isfinite(image.depth[i])) {
        const size_t col = i % static_cast<size_t>(image.width);
        const size_t row = i / static_cast<size_t>(image.width);
        return Error(StatusCode::kOutOfRange,
                     path,
                     "pixel (" + std::to_string(col) + ", " + std::to_string(row) +
                         "): depth on the hand is not finite");
      }
    }
  }
  return image;
}

Status WriteLabelExr(const fs::path& path,
                     const LabelImage& image,
                     const ExrWriteOptions& options) {
  const size_t n = static_cast<size_t>(image.width) * static_cast<size_t>(image.height);
  THROW_CHECK_EQ(image.labels.size(), n);
  THROW_CHECK(image.depth.empty() || image.depth.size() == n);
  // Channels in the order Blender writes them (alphabetical within the layer).
  std::vector<std::string> names;
  if (options.combined_pass) {
    for (const char* c : {"R", "G", "B", "A"}) names.push_back(options.layer + ".Combined." + c);
  }
  if (image.has_depth()) names.push_back(options.layer + "." + kDepthChannelSuffix);
  names.push_back(options.layer + "." + kLabelChannelSuffix);
  Imf::Compression compression = Imf::ZIP_COMPRESSION;
  if (!ParseCompression(options.compression, &compression)) {
    return Error(StatusCode::kInvalidArgument,
                 path,
                 "unknown EXR compression '" + options.compression + "'");
  }
  // One plane per channel, in the file's pixel type (OpenEXR converts types only when reading).
  std::vector<std::vector<float>> planes(names.size(), std::vector<float>(n, 0.0f));
  for (size_t i = 0; i < n; ++i) planes.back()[i] = image.labels[i];
  if (image.has_depth()) planes[names.size() - 2] = image.depth;
  std::vector<std::vector<Imath::half>> half_planes;
  if (options.half) {
    for (const std::vector<float>& plane : planes) {
      half_planes.emplace_back(plane.begin(), plane.end());
    }
  }
  MemoryOStream stream;
  try {
    Imf::Header header(image.width, image.height);
    header.compression() = compression;
    Imf::FrameBuffer frame;
    const Imf::PixelType type = options.half ? Imf::HALF : Imf::FLOAT;
    const size_t bytes = options.half ? sizeof(Imath::half) : sizeof(float);
    for (size_t c = 0; c < names.size(); ++c) {
      header.channels().insert(names[c], Imf::Channel(type));
      char* base = options.half ? reinterpret_cast<char*>(half_planes[c].data())
                                : reinterpret_cast<char*>(planes[c].data());
      frame.insert(names[c],
                   Imf::Slice(type, base, bytes, bytes * static_cast<size_t>(image.width)));
    }
    Imf::OutputFile out(stream, header, /*numThreads=*/1);
    out.setFrameBuffer(frame);
    out.writePixels(image.height);
  } catch (const std::exception& e) {
    return Error(StatusCode::kIoError, path, "EXR encoding failed: " + OneLine(e.what()));
  }
  return WriteFileAtomic(path, stream.bytes());
}

}  // namespace handdb
