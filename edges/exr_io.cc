#include "edges/exr_io.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
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

std::string OneLine(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s.empty() ? "unknown error" : s;
}

Status Error(StatusCode code, const fs::path& path, const std::string& what) {
  return Status(code, path.string() + ": " + what);
}

std::string FormatFloat(float v) {
  std::ostringstream os;
  os << v;
  return os.str();
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
  std::unique_ptr<OIIO::ImageInput> in = OIIO::ImageInput::open(path.string());
  if (!in) {
    return Error(
        StatusCode::kBadImage, path, "cannot read as an EXR image: " + OneLine(OIIO::geterror()));
  }
  if (std::string(in->format_name()) != "openexr") {
    in->close();
    return Error(StatusCode::kBadImage,
                 path,
                 std::string("not an OpenEXR file (detected ") + in->format_name() + ")");
  }
  // Blender writes one part; look through every subimage in case a tool split the layers.
  int label_sub = -1, label_ch = -1, depth_sub = -1, depth_ch = -1;
  std::vector<std::string> all_channels;
  for (int sub = 0; in->seek_subimage(sub, 0); ++sub) {
    const OIIO::ImageSpec& spec = in->spec();
    for (int c = 0; c < spec.nchannels; ++c) {
      const std::string& name = spec.channelnames[c];
      all_channels.push_back(name);
      if (label_ch < 0 && EndsWith(name, kLabelChannelSuffix)) {
        label_sub = sub;
        label_ch = c;
      }
      if (depth_ch < 0 && EndsWith(name, kDepthChannelSuffix)) {
        depth_sub = sub;
        depth_ch = c;
      }
    }
  }
  (void)in->geterror();  // seeking past the last subimage sets an error we do not care about
  auto channel_list = [&] {
    std::string s;
    for (const auto& c : all_channels) s += (s.empty() ? "" : ", ") + c;
    return s.empty() ? std::string("none") : s;
  };
  if (label_ch < 0) {
    return Error(StatusCode::kBadImage,
                 path,
                 std::string("no label channel ending in '") + kLabelChannelSuffix +
                     "' (channels: " + channel_list() + ")");
  }
  if (options.require_depth && depth_ch < 0) {
    return Error(StatusCode::kBadImage,
                 path,
                 std::string("no depth channel ending in '") + kDepthChannelSuffix +
                     "' (channels: " + channel_list() + ")");
  }

  LabelImage image;
  auto read_channel = [&](int sub, int ch, std::vector<float>* out) -> Status {
    if (!in->seek_subimage(sub, 0)) {
      return Error(StatusCode::kBadImage, path, "cannot seek to part " + std::to_string(sub));
    }
    const OIIO::ImageSpec& spec = in->spec();
    if (spec.x != 0 || spec.y != 0 || spec.width != spec.full_width ||
        spec.height != spec.full_height || spec.depth != 1) {
      return Error(StatusCode::kSizeMismatch,
                   path,
                   "data window " + std::to_string(spec.width) + "x" + std::to_string(spec.height) +
                       "+" + std::to_string(spec.x) + "+" + std::to_string(spec.y) +
                       " is not the full display window " + std::to_string(spec.full_width) + "x" +
                       std::to_string(spec.full_height));
    }
    if ((options.expected_width > 0 && spec.width != options.expected_width) ||
        (options.expected_height > 0 && spec.height != options.expected_height)) {
      return Error(StatusCode::kSizeMismatch,
                   path,
                   "image is " + std::to_string(spec.width) + "x" + std::to_string(spec.height) +
                       ", expected " + std::to_string(options.expected_width) + "x" +
                       std::to_string(options.expected_height));
    }
    if (image.width == 0) {
      image.width = spec.width;
      image.height = spec.height;
    } else if (image.width != spec.width || image.height != spec.height) {
      return Error(StatusCode::kSizeMismatch, path, "label and depth parts differ in size");
    }
    if (spec.width <= 0 || spec.height <= 0) {
      return Error(StatusCode::kSizeMismatch, path, "empty image");
    }
    out->resize(static_cast<size_t>(spec.width) * static_cast<size_t>(spec.height));
    if (!in->read_image(sub, 0, ch, ch + 1, OIIO::TypeDesc::FLOAT, out->data())) {
      return Error(StatusCode::kTruncated,
                   path,
                   "pixel data unreadable (truncated or corrupt): " + OneLine(in->geterror()));
    }
    return Status::Ok();
  };

  std::vector<float> label_values;
  HANDDB_RETURN_IF_ERROR(read_channel(label_sub, label_ch, &label_values));
  if (depth_ch >= 0) HANDDB_RETURN_IF_ERROR(read_channel(depth_sub, depth_ch, &image.depth));
  in->close();

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
  const size_t nch = names.size();
  OIIO::ImageSpec spec(image.width,
                       image.height,
                       static_cast<int>(nch),
                       options.half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
  spec.channelnames = names;
  spec.alpha_channel = -1;
  spec.z_channel = -1;
  spec.attribute("compression", options.compression);
  std::vector<float> pixels(n * nch, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    float* px = &pixels[i * nch + nch - 1];
    *px = image.labels[i];
    if (image.has_depth()) px[-1] = image.depth[i];
  }
  std::vector<unsigned char> bytes;
  OIIO::Filesystem::IOVecOutput proxy(bytes);
  std::unique_ptr<OIIO::ImageOutput> out = OIIO::ImageOutput::create("openexr");
  if (!out)
    return Error(StatusCode::kIoError, path, "no OpenEXR writer: " + OneLine(OIIO::geterror()));
  if (!out->set_ioproxy(&proxy)) {
    return Error(StatusCode::kIoError, path, "OpenEXR writer cannot write to memory");
  }
  if (!out->open(path.string(), spec) || !out->write_image(OIIO::TypeDesc::FLOAT, pixels.data()) ||
      !out->close()) {
    return Error(StatusCode::kIoError, path, "EXR encoding failed: " + OneLine(out->geterror()));
  }
  return WriteFileAtomic(
      path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

}  // namespace handdb
