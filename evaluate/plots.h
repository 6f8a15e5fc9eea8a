// PNG plots of an evaluation, drawn with OpenCV (no plotting library on the machine): the rank
// histogram of the paper's Table 1, empirical CDFs of keypoint error, and example sheets that
// overlay a test view's query edges on its best database match. Every file is written atomically.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "base/status.h"
#include "evaluate/metrics.h"
#include "format/roll.h"

namespace handdb {

// Bars for the seven bins of Table 1, each labelled with its count and share.
Status WriteRankHistogramPng(const std::filesystem::path& path,
                             const RankTable& table,
                             const std::string& title);

struct CdfSeries {
  std::string name;
  std::vector<double> values;           // NaN skipped
  std::array<uint8_t, 3> bgr{0, 0, 0};  // line colour
};
// Empirical CDFs on a shared x axis from 0 to `x_max` (<= 0: the largest value).
Status WriteCdfPng(const std::filesystem::path& path,
                   const std::vector<CdfSeries>& series,
                   const std::string& title,
                   const std::string& x_label,
                   double x_max);

// One tile of an example sheet: the query's edge points (blue) and the match's (red), both in a
// normalised frame (diameter kNormalisedDiameter, origin at the centre), and an optional image
// (e.g. the photo the query came from) shown on the left.
struct ExampleTile {
  std::string caption;   // first line, e.g. "test 17  rank 1"
  std::string caption2;  // second line, e.g. "kp err 0.05  dir 12 deg"
  std::vector<Point2f> query_points;
  std::vector<Point2f> match_points;
  std::filesystem::path image;  // empty: none; unreadable: a grey box
  // The top match's 21 keypoints in the image's pixels: its skeleton over the image (empty: none).
  std::vector<Point2f> skeleton_px;
};
Status WriteExampleSheetPng(const std::filesystem::path& path,
                            const std::vector<ExampleTile>& tiles,
                            const std::string& title);

// A confusion matrix: counts[r][c] for row labels `rows` (e.g. expected shape) and column labels
// `cols` (e.g. top-1 shape); cells shaded by their share of the row, diagonal-like cells (same
// label) outlined in green, column labels written vertically so long names stay readable.
Status WriteConfusionMatrixPng(const std::filesystem::path& path,
                               const std::vector<std::string>& rows,
                               const std::vector<std::string>& cols,
                               const std::vector<std::vector<int64_t>>& counts,
                               const std::string& title,
                               const std::string& row_axis,
                               const std::string& col_axis);

}  // namespace handdb
