// 2D keypoint annotations of real photos (`handdb evaluate DB --photos DIR --keypoints FILE`,
// schemas/photo_keypoints.schema.json, docs/evaluation.md) and the 2D keypoint error of a match.
//
// The file maps each annotated photo, named by its path relative to DIR exactly as the report names
// it ("asl-3/IMG_0001.jpg"), to its 21 keypoints in the project's order (docs/conventions.md:
// wrist, thumb CMC..tip, index MCP..tip, middle, ring, pinky) as [x, y] in the photo's pixels
// (origin at the top-left corner of the top-left pixel, pixel centres at integer + 0.5: the frame
// of `handdb query --json`'s keypoints_image_px), optionally [x, y, false] for a keypoint the
// annotator could not see; those are left out of every error and of the hand size.
//
// Error of a match (its keypoints mapped into the photo's pixels, mirrored back for a left hand):
// the plain 2D distance per visible keypoint (no root alignment: the search places the hand, too),
// divided by the hand size = the diagonal of the bounding box of the photo's visible annotated
// keypoints. A photo's error is the mean over its visible keypoints; PCK@t is the share of visible
// keypoints within t hand sizes.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/roll.h"
#include "format/view.h"

namespace handdb {

// PCK thresholds, in hand sizes (reports give PCK at each).
inline constexpr std::array<double, 3> kPckThresholds = {0.05, 0.1, 0.2};

// How the hand size is measured, for reports.
inline constexpr char kHandSizeRule[] =
    "diagonal of the bounding box of the visible annotated keypoints (px)";

struct PhotoKeypoints {
  std::array<Point2f, kNumKeypoints> px{};  // the photo's pixels
  std::array<bool, kNumKeypoints> visible{};
  double hand_size_px = 0;  // HandSizePx(*this), set by the reader
  int NumVisible() const;
};

// The diagonal of the bounding box of the visible keypoints (0 with fewer than two).
double HandSizePx(const PhotoKeypoints& keypoints);

struct PhotoKeypointFile {
  std::filesystem::path path;
  std::map<std::string, PhotoKeypoints> images;  // key: the photo's path relative to DIR
};

// A JSON document already checked against photo_keypoints.schema.json -> its annotations, with the
// checks the schema cannot make, each one line naming `where` and the image: a key that is not a
// plain relative path ("asl-3/x.jpg": no leading '/', no '.', '..' or empty parts, no '\'), fewer
// than two visible keypoints, or all of them at one point (no hand size). kInvalidArgument.
Result<PhotoKeypointFile> PhotoKeypointsFromJson(const nlohmann::json& doc,
                                                 const std::string& where);

// Reads, schema-checks (base/json_schema.h: "<file>: <json pointer>: <problem>") and checks a
// --keypoints file.
Result<PhotoKeypointFile> ReadPhotoKeypoints(const std::filesystem::path& path);

// Per keypoint, the distance (px) between `predicted` (21 points in the photo's pixels) and the
// annotation; NaN where the annotation is not visible.
std::array<double, kNumKeypoints> KeypointDistancesPx(const PhotoKeypoints& truth,
                                                      std::span<const Point2f> predicted);

// The mean of the finite `distances_px` divided by `hand_size_px` (NaN when none is finite).
double MeanKeypointError(std::span<const double> distances_px, double hand_size_px);

}  // namespace handdb
