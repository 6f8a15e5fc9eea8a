#include "evaluate/photo_keypoints.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "base/json_schema.h"

namespace handdb {
namespace {

using json = nlohmann::json;

// "asl-3/IMG_1.jpg": '/'-separated, relative, no '.', '..' or empty parts, no backslash.
bool IsPlainRelativePath(const std::string& key) {
  if (key.empty() || key.find('\\') != std::string::npos) return false;
  size_t pos = 0;
  while (true) {
    const size_t slash = key.find('/', pos);
    const std::string part = key.substr(pos, slash == std::string::npos ? slash : slash - pos);
    if (part.empty() || part == "." || part == "..") return false;
    if (slash == std::string::npos) return true;
    pos = slash + 1;
  }
}

}  // namespace

int PhotoKeypoints::NumVisible() const {
  return static_cast<int>(std::count(visible.begin(), visible.end(), true));
}

double HandSizePx(const PhotoKeypoints& keypoints) {
  if (keypoints.NumVisible() < 2) return 0;
  double x0 = std::numeric_limits<double>::infinity(), y0 = x0;
  double x1 = -x0, y1 = -x0;
  for (int k = 0; k < kNumKeypoints; ++k) {
    if (!keypoints.visible[k]) continue;
    x0 = std::min<double>(x0, keypoints.px[k].x);
    x1 = std::max<double>(x1, keypoints.px[k].x);
    y0 = std::min<double>(y0, keypoints.px[k].y);
    y1 = std::max<double>(y1, keypoints.px[k].y);
  }
  return std::hypot(x1 - x0, y1 - y0);
}

Result<PhotoKeypointFile> PhotoKeypointsFromJson(const json& doc, const std::string& where) {
  PhotoKeypointFile file;
  file.path = where;
  for (const auto& [key, list] : doc.at("images").items()) {
    const std::string image = where + ": images[\"" + key + "\"]";
    if (!IsPlainRelativePath(key)) {
      return Status(StatusCode::kInvalidArgument,
                    image +
                        ": not a path relative to the photo directory (write it as the report "
                        "names the photo: <shape folder>/<file>)");
    }
    PhotoKeypoints kp;
    for (int k = 0; k < kNumKeypoints; ++k) {
      const json& point = list.at(k);
      kp.px[k] = {point.at(0).get<float>(), point.at(1).get<float>()};
      kp.visible[k] = point.size() < 3 || point.at(2).get<bool>();
      if (!std::isfinite(kp.px[k].x) || !std::isfinite(kp.px[k].y)) {
        return Status(StatusCode::kInvalidArgument,
                      image + "[" + std::to_string(k) + "]: " + point.dump() +
                          " is too large for a pixel coordinate");
      }
    }
    if (kp.NumVisible() < 2) {
      return Status(StatusCode::kInvalidArgument,
                    image + ": " + std::to_string(kp.NumVisible()) +
                        " visible keypoints; at least two are needed to measure the hand size");
    }
    kp.hand_size_px = HandSizePx(kp);
    if (!(kp.hand_size_px > 0)) {
      return Status(StatusCode::kInvalidArgument,
                    image +
                        ": every visible keypoint is at the same point (the hand size, the "
                        "diagonal of their bounding box, is 0)");
    }
    file.images.emplace(key, kp);
  }
  return file;
}

Result<PhotoKeypointFile> ReadPhotoKeypoints(const std::filesystem::path& path) {
  auto doc = ReadJsonFile(path, "photo_keypoints.schema.json");
  if (!doc.ok()) return doc.status();
  return PhotoKeypointsFromJson(*doc, path.string());
}

std::array<double, kNumKeypoints> KeypointDistancesPx(const PhotoKeypoints& truth,
                                                      std::span<const Point2f> predicted) {
  THROW_CHECK_EQ(predicted.size(), static_cast<size_t>(kNumKeypoints));
  std::array<double, kNumKeypoints> d;
  for (int k = 0; k < kNumKeypoints; ++k) {
    d[k] = truth.visible[k] ? std::hypot(static_cast<double>(predicted[k].x) - truth.px[k].x,
                                         static_cast<double>(predicted[k].y) - truth.px[k].y)
                            : std::numeric_limits<double>::quiet_NaN();
  }
  return d;
}

double MeanKeypointError(std::span<const double> distances_px, double hand_size_px) {
  double sum = 0;
  int n = 0;
  for (double d : distances_px) {
    if (std::isfinite(d)) {
      sum += d;
      ++n;
    }
  }
  if (n == 0 || !(hand_size_px > 0)) return std::numeric_limits<double>::quiet_NaN();
  return sum / n / hand_size_px;
}

}  // namespace handdb
