// A contact sheet PNG for one query, so a person sees at a glance whether the answer is right:
// the input image (with its edges in green), the query's normalised edges, then one tile per
// match with the match's edges (black) over the query's (light red) and a caption
// "#rank  D_c  shape  roll".
#pragma once

#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/view.h"
#include "photo/image_edges.h"

namespace handdb {

struct SheetTile {
  std::string caption;
  std::vector<PointQ> points;  // normalised frame (for a match: the rolled view)
};

struct ContactSheetOptions {
  int tile_px = 240;  // square tiles
  int columns = 4;
  float extent_px = 175;  // normalised frame shown: [-extent, extent]^2
  bool Check() const;
};

// `input_image` may be empty (no input tile); `picture` gives the input's edge pixels, the
// normalised query points and the landmarks drawn over the input. `skeleton_px`, if not empty, is
// the top match's 21 keypoints (docs/conventions.md order) in the input picture's pixels: its
// skeleton is drawn over the input. Written atomically. kBadImage if the input cannot be read,
// kIoError on write failure.
Status WriteContactSheet(const std::filesystem::path& out_png,
                         const std::filesystem::path& input_image,
                         const PictureEvidence& picture,
                         std::span<const SheetTile> matches,
                         const ContactSheetOptions& options,
                         std::span<const Point2f> skeleton_px = {});

// A video frame's overlay: the picture (the file `input_image`, or `pixels` when given) with the
// skeleton of 21 keypoints in its px drawn as the contact sheet draws it (none when empty),
// written atomically as a PNG. Errors: the picture's (kBadImage, kNotFound), kIoError.
Status WriteSkeletonOverlay(const std::filesystem::path& out_png,
                            const std::filesystem::path& input_image,
                            const PicturePixels* pixels,
                            std::span<const Point2f> skeleton_px);

}  // namespace handdb
