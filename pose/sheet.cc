#include "pose/sheet.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "base/atomic_file.h"
#include "base/image_encode.h"
#include "base/image_file.h"
#include "format/skeleton.h"
#include "photo/image_read.h"

namespace handdb {
namespace {

const cv::Scalar kWhite(255, 255, 255);
const cv::Scalar kBlack(0, 0, 0);
const cv::Scalar kQueryColour(150, 150, 255);  // light red (BGR)
const cv::Scalar kGreen(0, 200, 0);
constexpr int kCaptionPx = 22;

void DrawPoints(cv::Mat& tile,
                std::span<const PointQ> pts,
                const cv::Scalar& colour,
                const ContactSheetOptions& o) {
  const double s = o.tile_px / (2.0 * o.extent_px);
  const cv::Vec3b c(static_cast<uint8_t>(colour[0]),
                    static_cast<uint8_t>(colour[1]),
                    static_cast<uint8_t>(colour[2]));
  for (const PointQ& p : pts) {
    const int x = static_cast<int>(std::floor((PointQToPx(p.x) + o.extent_px) * s));
    const int y = static_cast<int>(std::floor((PointQToPx(p.y) + o.extent_px) * s)) + kCaptionPx;
    if (x >= 0 && x < tile.cols && y >= kCaptionPx && y < tile.rows) tile.at<cv::Vec3b>(y, x) = c;
  }
}

void Caption(cv::Mat& tile, const std::string& text) {
  cv::putText(tile, text, {4, 16}, cv::FONT_HERSHEY_SIMPLEX, 0.42, kBlack, 1, cv::LINE_AA);
}

// The bones (amber) and joints (black) of 21 keypoints, each mapped to the image by `to_image`.
template <typename ToImage>
void DrawSkeleton(cv::Mat& image, std::span<const Point2f> skeleton_px, ToImage to_image) {
  const cv::Scalar bone(0, 215, 255);  // amber (BGR)
  for (const auto& b : kSkeletonBones) {
    cv::line(image,
             to_image(skeleton_px[b[0]].x, skeleton_px[b[0]].y),
             to_image(skeleton_px[b[1]].x, skeleton_px[b[1]].y),
             bone,
             2,
             cv::LINE_AA);
  }
  for (const Point2f& k : skeleton_px) {
    cv::circle(image, to_image(k.x, k.y), 2, kBlack, cv::FILLED, cv::LINE_AA);
  }
}

Status WritePng(const std::filesystem::path& out_png, const cv::Mat& image) {
  auto png = EncodePng({image.data, image.cols, image.rows, image.channels(), image.step[0]});
  if (!png.ok()) {
    return Status(StatusCode::kIoError,
                  out_png.string() + ": PNG encoding failed: " + png.status().message());
  }
  return WriteFileAtomic(out_png,
                         std::string_view(reinterpret_cast<const char*>(png->data()), png->size()));
}

}  // namespace

bool ContactSheetOptions::Check() const {
  CHECK_OPTION_GE(tile_px, 64);
  CHECK_OPTION_LE(tile_px, 2048);
  CHECK_OPTION_GE(columns, 1);
  CHECK_OPTION_GT(extent_px, 0.0f);
  return true;
}

Status WriteContactSheet(const std::filesystem::path& out_png,
                         const std::filesystem::path& input_image,
                         const PictureEvidence& picture,
                         std::span<const SheetTile> matches,
                         const ContactSheetOptions& options,
                         std::span<const Point2f> skeleton_px) {
  THROW_CHECK(options.Check());
  const QueryEdges& query = picture.edges;
  THROW_CHECK(skeleton_px.empty() || skeleton_px.size() == kNumKeypoints);
  const int t = options.tile_px;
  const int th = t + kCaptionPx;
  std::vector<cv::Mat> tiles;

  if (!input_image.empty()) {
    // A huge JPEG is read reduced (as the query read it); edge pixels are in the file's pixels.
    int flags = cv::IMREAD_COLOR;
    if (const auto size = ReadImageSize(input_image);
        size && size->width * size->height > kMaxImagePixels) {
      flags = cv::IMREAD_REDUCED_COLOR_8;
    }
    cv::Mat img = query.kind == QueryInputKind::kLabels
                      ? cv::Mat()
                      : ReadImage(input_image, flags).value_or(cv::Mat());

    cv::Mat tile(th, t, CV_8UC3, kWhite);
    if (img.empty()) {
      // Label EXRs are not images OpenCV reads: draw the source edge pixels instead.
      img = cv::Mat(std::max(query.height, 1), std::max(query.width, 1), CV_8UC3, kWhite);
    }
    // Picture px per source px (below 1 for a JPEG read reduced).
    const double f = query.width > 0 ? static_cast<double>(img.cols) / query.width : 1.0;
    for (const EdgePixelXY& p : query.edge_pixels) {
      const int x = static_cast<int>(p.x * f), y = static_cast<int>(p.y * f);
      if (x >= 0 && y >= 0 && x < img.cols && y < img.rows) {
        img.at<cv::Vec3b>(y, x) = cv::Vec3b(0, 200, 0);
      }
    }
    const double s = std::min(static_cast<double>(t) / img.cols, static_cast<double>(t) / img.rows);
    cv::Mat small;
    cv::resize(
        img,
        small,
        {std::max(1, static_cast<int>(img.cols * s)), std::max(1, static_cast<int>(img.rows * s))},
        0,
        0,
        cv::INTER_AREA);
    const cv::Point2d at((t - small.cols) / 2, kCaptionPx + (t - small.rows) / 2);
    small.copyTo(
        tile(cv::Rect(static_cast<int>(at.x), static_cast<int>(at.y), small.cols, small.rows)));
    // The palm circle and the wrist cut (photo path), in the tile's pixels.
    const auto to_tile = [&](double x, double y) {
      return cv::Point(static_cast<int>(std::lround(at.x + x * f * s)),
                       static_cast<int>(std::lround(at.y + y * f * s)));
    };
    if (query.palm_radius_px > 0) {
      cv::circle(tile,
                 to_tile(query.palm_centre_x, query.palm_centre_y),
                 std::max(1, static_cast<int>(std::lround(query.palm_radius_px * f * s))),
                 cv::Scalar(255, 160, 0),
                 1,
                 cv::LINE_AA);
    }
    if (!skeleton_px.empty()) DrawSkeleton(tile, skeleton_px, to_tile);
    // The landmark network's joints (docs/query.md, "Hand landmarks") as small magenta rings,
    // so the top match's skeleton can be read against what the network saw.
    if (picture.landmarks) {
      for (const Point2f& k : picture.landmarks->image_px) {
        cv::circle(tile, to_tile(k.x, k.y), 3, cv::Scalar(200, 0, 200), 1, cv::LINE_AA);
      }
    }
    if (query.forearm_cut) {
      cv::line(tile,
               to_tile(query.wrist_line[0], query.wrist_line[1]),
               to_tile(query.wrist_line[2], query.wrist_line[3]),
               cv::Scalar(0, 0, 230),
               2,
               cv::LINE_AA);
    }
    Caption(tile, "input (" + std::string(QueryInputKindName(query.kind)) + ")");
    tiles.push_back(tile);
  }
  {
    cv::Mat tile(th, t, CV_8UC3, kWhite);
    DrawPoints(tile, query.points, kBlack, options);
    Caption(tile, "query: " + std::to_string(query.points.size()) + " edge points");
    tiles.push_back(tile);
  }
  for (const SheetTile& m : matches) {
    cv::Mat tile(th, t, CV_8UC3, kWhite);
    DrawPoints(tile, query.points, kQueryColour, options);
    DrawPoints(tile, m.points, kBlack, options);
    Caption(tile, m.caption);
    tiles.push_back(tile);
  }
  const int cols = std::min<int>(options.columns, static_cast<int>(tiles.size()));
  const int rows = (static_cast<int>(tiles.size()) + cols - 1) / cols;
  cv::Mat sheet(
      rows * th + (rows + 1) * 4, cols * t + (cols + 1) * 4, CV_8UC3, cv::Scalar(200, 200, 200));
  for (size_t i = 0; i < tiles.size(); ++i) {
    const int r = static_cast<int>(i) / cols;
    const int c = static_cast<int>(i) % cols;
    tiles[i].copyTo(sheet(cv::Rect(4 + c * (t + 4), 4 + r * (th + 4), t, th)));
  }
  return WritePng(out_png, sheet);
}

Status WriteSkeletonOverlay(const std::filesystem::path& out_png,
                            const std::filesystem::path& input_image,
                            const PicturePixels* pixels,
                            std::span<const Point2f> skeleton_px) {
  THROW_CHECK(skeleton_px.empty() || skeleton_px.size() == kNumKeypoints);
  cv::Mat image;
  if (pixels != nullptr) {
    const cv::Mat view(pixels->height,
                       pixels->width,
                       CV_MAKETYPE(CV_8U, pixels->channels),
                       const_cast<uint8_t*>(pixels->data),
                       pixels->row_bytes != 0
                           ? pixels->row_bytes
                           : static_cast<size_t>(pixels->width) * pixels->channels);
    if (pixels->channels == 1) {
      cv::cvtColor(view, image, cv::COLOR_GRAY2BGR);
    } else if (pixels->channels == 4) {
      cv::cvtColor(view, image, cv::COLOR_BGRA2BGR);
    } else {
      image = view.clone();
    }
  } else {
    Result<cv::Mat> read = ReadImage(input_image, cv::IMREAD_COLOR);
    if (!read.ok()) return read.status();
    image = std::move(read).value();
  }
  DrawSkeleton(image, skeleton_px, [](double x, double y) {
    return cv::Point(static_cast<int>(std::lround(x - 0.5)),
                     static_cast<int>(std::lround(y - 0.5)));
  });
  return WritePng(out_png, image);
}

}  // namespace handdb
