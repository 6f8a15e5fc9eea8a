#include "evaluate/plots.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "base/atomic_file.h"
#include "base/image_encode.h"
#include "base/image_file.h"
#include "format/skeleton.h"
#include "photo/image_read.h"

namespace handdb {
namespace {

const cv::Scalar kWhite(255, 255, 255);
const cv::Scalar kBlack(0, 0, 0);
const cv::Scalar kGrey(200, 200, 200);
const cv::Scalar kDarkGrey(110, 110, 110);
constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;

Status WritePng(const std::filesystem::path& path, const cv::Mat& image) {
  THROW_CHECK_EQ(image.depth(), CV_8U);
  auto bytes = EncodePng({image.data, image.cols, image.rows, image.channels(), image.step[0]});
  if (!bytes.ok()) {
    return Status(StatusCode::kIoError,
                  path.string() + ": PNG encoding failed: " + bytes.status().message());
  }
  return WriteFileAtomic(
      path, std::string_view(reinterpret_cast<const char*>(bytes->data()), bytes->size()));
}

void Text(cv::Mat& image,
          const std::string& text,
          cv::Point at,
          double scale = 0.5,
          const cv::Scalar& colour = kBlack) {
  cv::putText(image, text, at, kFont, scale, colour, 1, cv::LINE_AA);
}

void CentredText(cv::Mat& image, const std::string& text, int centre_x, int y, double scale = 0.5) {
  int baseline = 0;
  const cv::Size size = cv::getTextSize(text, kFont, scale, 1, &baseline);
  Text(image, text, {centre_x - size.width / 2, y}, scale);
}

std::string Format(const char* fmt, double value) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, value);
  return buf;
}

}  // namespace

Status WriteRankHistogramPng(const std::filesystem::path& path,
                             const RankTable& table,
                             const std::string& title) {
  constexpr int kWidth = 760;
  constexpr int kHeight = 420;
  constexpr int kLeft = 60;
  constexpr int kRight = 20;
  constexpr int kTop = 50;
  constexpr int kBottom = 60;
  cv::Mat image(kHeight, kWidth, CV_8UC3, kWhite);
  Text(image, title, {kLeft, 28}, 0.6);
  const int64_t total = table.total();
  const int64_t max_count =
      std::max<int64_t>(1, *std::max_element(table.counts.begin(), table.counts.end()));
  const int plot_w = kWidth - kLeft - kRight;
  const int plot_h = kHeight - kTop - kBottom;
  const int slot = plot_w / kNumRankBins;
  // Axes and a few horizontal grid lines.
  for (int g = 0; g <= 4; ++g) {
    const int y = kTop + plot_h - plot_h * g / 4;
    cv::line(image, {kLeft, y}, {kLeft + plot_w, y}, g == 0 ? kBlack : kGrey, 1);
    Text(image, std::to_string(max_count * g / 4), {8, y + 5}, 0.4, kDarkGrey);
  }
  for (int bin = 0; bin < kNumRankBins; ++bin) {
    const int64_t count = table.counts[bin];
    const int bar_h =
        static_cast<int>(std::lround(static_cast<double>(plot_h) * count / max_count));
    const int x0 = kLeft + bin * slot + slot / 6;
    const int x1 = kLeft + (bin + 1) * slot - slot / 6;
    const int y1 = kTop + plot_h;
    // The last bin (no correct match within rank 1024) in red, the others from green to orange.
    const cv::Scalar colour = bin == kNumRankBins - 1
                                  ? cv::Scalar(60, 60, 210)
                                  : cv::Scalar(80, 170 - 15 * bin, 40 + 30 * bin);
    if (bar_h > 0) cv::rectangle(image, {x0, y1 - bar_h}, {x1, y1}, colour, cv::FILLED);
    const int cx = (x0 + x1) / 2;
    const double share =
        total > 0 ? 100.0 * static_cast<double>(count) / static_cast<double>(total) : 0;
    CentredText(image, std::to_string(count), cx, y1 - bar_h - 18, 0.5);
    CentredText(image, Format("%.0f%%", share), cx, y1 - bar_h - 4, 0.4);
    CentredText(image, std::string(RankBinName(bin)), cx, y1 + 20, 0.5);
  }
  CentredText(
      image,
      "rank of the highest-ranking correct match (" + std::to_string(total) + " test views)",
      kLeft + plot_w / 2,
      kHeight - 15,
      0.5);
  return WritePng(path, image);
}

Status WriteCdfPng(const std::filesystem::path& path,
                   const std::vector<CdfSeries>& series,
                   const std::string& title,
                   const std::string& x_label,
                   double x_max) {
  constexpr int kWidth = 760;
  constexpr int kHeight = 440;
  constexpr int kLeft = 60;
  constexpr int kRight = 30;
  constexpr int kTop = 50;
  constexpr int kBottom = 60;
  if (x_max <= 0) {
    for (const auto& s : series) {
      for (double v : s.values) {
        if (!std::isnan(v)) x_max = std::max(x_max, v);
      }
    }
    if (x_max <= 0) x_max = 1;
    // A round axis end: the next tenth (or whole number above 10).
    x_max = x_max < 10 ? std::ceil(x_max * 10.0 - 1e-9) / 10.0 : std::ceil(x_max);
  }
  cv::Mat image(kHeight, kWidth, CV_8UC3, kWhite);
  Text(image, title, {kLeft, 28}, 0.6);
  const int plot_w = kWidth - kLeft - kRight;
  const int plot_h = kHeight - kTop - kBottom;
  auto to_px = [&](double x, double y) {
    const double cx = std::clamp(x / x_max, 0.0, 1.0);
    return cv::Point(kLeft + static_cast<int>(std::lround(cx * plot_w)),
                     kTop + plot_h - static_cast<int>(std::lround(y * plot_h)));
  };
  for (int g = 0; g <= 4; ++g) {
    const double f = g / 4.0;
    cv::line(image, to_px(0, f), to_px(x_max, f), g == 0 ? kBlack : kGrey, 1);
    cv::line(image, to_px(x_max * f, 0), to_px(x_max * f, 1), g == 0 ? kBlack : kGrey, 1);
    Text(image, Format("%.2f", f), {12, to_px(0, f).y + 5}, 0.4, kDarkGrey);
    CentredText(image,
                Format(x_max < 10 ? "%.2f" : "%.0f", x_max * f),
                to_px(x_max * f, 0).x,
                kTop + plot_h + 18,
                0.4);
  }
  CentredText(image, x_label, kLeft + plot_w / 2, kHeight - 15, 0.5);
  for (const auto& s : series) {
    const cv::Scalar colour(s.bgr[0], s.bgr[1], s.bgr[2]);
    const auto cdf = EmpiricalCdf(s.values);
    // A step function: horizontal to the next value, then up.
    cv::Point previous = to_px(0, 0);
    for (const auto& [x, y] : cdf) {
      const cv::Point flat(to_px(x, 0).x, previous.y);
      cv::line(image, previous, flat, colour, 2, cv::LINE_AA);
      const cv::Point up = to_px(x, y);
      cv::line(image, flat, up, colour, 2, cv::LINE_AA);
      previous = up;
    }
    if (!cdf.empty()) {
      cv::line(image, previous, {kLeft + plot_w, previous.y}, colour, 2, cv::LINE_AA);
    }
  }
  // Legend in the lower right (where risen CDFs leave room), on a white box over the grid.
  if (!series.empty()) {
    constexpr int kLegendWidth = 400;
    const int legend_x = kLeft + plot_w - kLegendWidth;
    int legend_y = kTop + plot_h - 14 - 22 * static_cast<int>(series.size() - 1);
    cv::rectangle(image,
                  {legend_x - 8, legend_y - 18},
                  {kLeft + plot_w - 4, kTop + plot_h - 4},
                  kWhite,
                  cv::FILLED);
    for (const auto& s : series) {
      const cv::Scalar colour(s.bgr[0], s.bgr[1], s.bgr[2]);
      const Summary summary = Summarise(s.values);
      cv::line(image, {legend_x, legend_y - 5}, {legend_x + 30, legend_y - 5}, colour, 2);
      Text(image,
           s.name + Format("  median %.3f", summary.median) + Format("  mean %.3f", summary.mean),
           {legend_x + 38, legend_y},
           0.45);
      legend_y += 22;
    }
  }
  return WritePng(path, image);
}

Status WriteExampleSheetPng(const std::filesystem::path& path,
                            const std::vector<ExampleTile>& tiles,
                            const std::string& title) {
  constexpr int kPanel = 220;  // one square panel
  constexpr int kCaption = 44;
  constexpr int kTitle = 36;
  constexpr int kMaxColumns = 2;
  const bool any_image = std::any_of(
      tiles.begin(), tiles.end(), [](const ExampleTile& t) { return !t.image.empty(); });
  const int panels_per_tile = any_image ? 2 : 1;
  const int tile_w = panels_per_tile * kPanel + 10;
  const int tile_h = kPanel + kCaption;
  const int columns = std::max(1, std::min<int>(kMaxColumns, static_cast<int>(tiles.size())));
  const int rows = std::max<int>(1, (static_cast<int>(tiles.size()) + columns - 1) / columns);
  cv::Mat sheet(kTitle + rows * tile_h, columns * tile_w, CV_8UC3, kWhite);
  Text(sheet, title, {8, 24}, 0.6);
  // The normalised frame spans about one diameter; leave a margin around it.
  const double scale = kPanel / (kNormalisedDiameter * 1.25);
  for (size_t i = 0; i < tiles.size(); ++i) {
    const ExampleTile& tile = tiles[i];
    const int ox = static_cast<int>(i % columns) * tile_w;
    const int oy = kTitle + static_cast<int>(i / columns) * tile_h;
    int px = ox;
    if (any_image) {
      cv::Mat panel(kPanel, kPanel, CV_8UC3, kGrey);
      if (!tile.image.empty()) {
        // A huge JPEG is read at 1/8 (as the query read it reduced); keypoints are in the file's
        // pixels.
        const std::optional<ImageSize> size = ReadImageSize(tile.image);
        const bool huge = size && size->width * size->height > kMaxImagePixels;
        cv::Mat img = ReadImage(tile.image, huge ? cv::IMREAD_REDUCED_COLOR_8 : cv::IMREAD_COLOR)
                          .value_or(cv::Mat());
        if (!img.empty()) {
          cv::resize(img, panel, panel.size(), 0, 0, cv::INTER_AREA);
          const double sx = double(kPanel) / (huge ? size->width : img.cols);
          const double sy = double(kPanel) / (huge ? size->height : img.rows);
          if (tile.skeleton_px.size() == kNumKeypoints) {
            const auto at = [&](int k) {
              return cv::Point(static_cast<int>(std::lround(tile.skeleton_px[k].x * sx)),
                               static_cast<int>(std::lround(tile.skeleton_px[k].y * sy)));
            };
            for (const auto& b : kSkeletonBones) {
              cv::line(panel, at(b[0]), at(b[1]), cv::Scalar(0, 215, 255), 2, cv::LINE_AA);
            }
            for (int k = 0; k < kNumKeypoints; ++k) {
              cv::circle(panel, at(k), 2, cv::Scalar(0, 0, 0), cv::FILLED, cv::LINE_AA);
            }
          }
        }
      }
      panel.copyTo(sheet(cv::Rect(px, oy, kPanel, kPanel)));
      px += kPanel;
    }
    cv::Mat panel(kPanel, kPanel, CV_8UC3, kWhite);
    cv::rectangle(panel, {0, 0}, {kPanel - 1, kPanel - 1}, kGrey, 1);
    auto draw = [&](const std::vector<Point2f>& points, const cv::Scalar& colour) {
      for (const Point2f& p : points) {
        const int x = static_cast<int>(std::lround(kPanel / 2.0 + p.x * scale));
        const int y = static_cast<int>(std::lround(kPanel / 2.0 + p.y * scale));
        if (x >= 0 && y >= 0 && x < kPanel && y < kPanel)
          panel.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uint8_t>(colour[0]),
                                                static_cast<uint8_t>(colour[1]),
                                                static_cast<uint8_t>(colour[2]));
      }
    };
    draw(tile.match_points, cv::Scalar(40, 40, 220));
    draw(tile.query_points, cv::Scalar(200, 90, 20));
    panel.copyTo(sheet(cv::Rect(px, oy, kPanel, kPanel)));
    Text(sheet, tile.caption, {ox + 4, oy + kPanel + 17}, 0.45);
    Text(sheet, tile.caption2, {ox + 4, oy + kPanel + 36}, 0.4, kDarkGrey);
  }
  return WritePng(path, sheet);
}

Status WriteConfusionMatrixPng(const std::filesystem::path& path,
                               const std::vector<std::string>& rows,
                               const std::vector<std::string>& cols,
                               const std::vector<std::vector<int64_t>>& counts,
                               const std::string& title,
                               const std::string& row_axis,
                               const std::string& col_axis) {
  THROW_CHECK_EQ(counts.size(), rows.size());
  constexpr int kCell = 34;
  constexpr double kLabelScale = 0.45;
  int baseline = 0;
  int label_w = 0;  // widest label, for the left margin and the vertical column labels
  for (const auto* labels : {&rows, &cols}) {
    for (const std::string& l : *labels) {
      label_w = std::max(label_w, cv::getTextSize(l, kFont, kLabelScale, 1, &baseline).width);
    }
  }
  const int left = label_w + 40;
  const int top = 50 + label_w + 12;
  const int n_rows = static_cast<int>(rows.size());
  const int n_cols = static_cast<int>(cols.size());
  const int width = std::max(left + n_cols * kCell + 70, 420);
  const int height = top + n_rows * kCell + 40;
  cv::Mat image(height, width, CV_8UC3, kWhite);
  Text(image, title, {8, 24}, 0.6);
  Text(image, col_axis + " (columns)", {left, 44}, 0.45, kDarkGrey);
  // Column labels: drawn horizontally into a strip, rotated to read bottom-up.
  for (int c = 0; c < n_cols; ++c) {
    cv::Mat strip(kCell, label_w + 8, CV_8UC3, kWhite);
    Text(strip, cols[c], {4, kCell / 2 + 5}, kLabelScale);
    cv::Mat rotated;
    cv::rotate(strip, rotated, cv::ROTATE_90_COUNTERCLOCKWISE);
    rotated.copyTo(image(cv::Rect(left + c * kCell, top - rotated.rows - 4, kCell, rotated.rows)));
  }
  for (int r = 0; r < n_rows; ++r) {
    THROW_CHECK_EQ(counts[r].size(), cols.size());
    int64_t row_total = 0;
    for (int64_t v : counts[r]) row_total += v;
    const int y0 = top + r * kCell;
    const int text_w = cv::getTextSize(rows[r], kFont, kLabelScale, 1, &baseline).width;
    Text(image, rows[r], {left - 8 - text_w, y0 + kCell / 2 + 5}, kLabelScale);
    for (int c = 0; c < n_cols; ++c) {
      const int64_t v = counts[r][c];
      const double share = row_total > 0 ? static_cast<double>(v) / row_total : 0;
      const int x0 = left + c * kCell;
      // White to dark blue with the row share; text turns white on dark cells.
      const cv::Scalar fill(255 - 105 * share, 255 - 200 * share, 255 - 225 * share);
      cv::rectangle(image, {x0, y0}, {x0 + kCell, y0 + kCell}, fill, cv::FILLED);
      cv::rectangle(image, {x0, y0}, {x0 + kCell, y0 + kCell}, kGrey, 1);
      if (v > 0) {
        const std::string text = std::to_string(v);
        const int tw = cv::getTextSize(text, kFont, 0.45, 1, &baseline).width;
        Text(image,
             text,
             {x0 + (kCell - tw) / 2, y0 + kCell / 2 + 5},
             0.45,
             share > 0.5 ? kWhite : kBlack);
      }
    }
    for (int c = 0; c < n_cols; ++c) {
      if (cols[c] == rows[r]) {
        const int x0 = left + c * kCell;
        cv::rectangle(image, {x0, y0}, {x0 + kCell, y0 + kCell}, cv::Scalar(40, 160, 40), 2);
      }
    }
    Text(image,
         std::to_string(row_total),
         {left + n_cols * kCell + 8, y0 + kCell / 2 + 5},
         0.4,
         kDarkGrey);
  }
  Text(image, row_axis + " (rows)", {8, height - 14}, 0.45, kDarkGrey);
  return WritePng(path, image);
}

}  // namespace handdb
