// From a picture to a query: edge points in the database's normalised frame.
//
// Three kinds of input (docs/query.md):
//  - a photo (PNG/JPEG): the hand is found by skin colour (a documented, tunable YCrCb box), or
//    given by --mask (non-zero = hand), optionally restricted to --roi; the largest connected
//    region is the hand. Edges = the silhouette contour plus the Canny edges (OpenCV) inside the
//    hand region, except those within `contour_clearance_px` of the contour (one outline, as in
//    the database's views, not Canny's outline beside the contour's);
//  - an edge image (non-zero pixels are edges);
//  - a Blender label EXR (clean synthetic edges through the converter's own code:
//    edges/exr_io.h + edges/view_conversion.h, BorderContact::kAllow).
// Then exactly the database's normalisation (edges/normalise.h, the converter's code): the
// silhouette's diameter is scaled to 192 px and its centre rule applied, points quantised to
// PointQ. For edge images the silhouette is unknown and all edge pixels stand in for it (the
// outline is among them, so their convex hull, which is all the normalisation looks at, is the
// same).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "edges/edges.h"
#include "format/roll.h"
#include "format/view.h"

namespace handdb {

enum class QueryInputKind { kAuto, kPhoto, kEdges, kLabels };
std::string_view QueryInputKindName(QueryInputKind kind);  // "auto", "photo", "edges", "labels"
Result<QueryInputKind> ParseQueryInputKind(std::string_view name);

// Skin colour model: a pixel is skin when its YCrCb components (OpenCV's 8-bit conversion) lie
// in these inclusive ranges. The defaults are the widely used Chai & Ngan (1999) box
// Cr 133..173, Cb 77..127, with very dark pixels (Y < 40) excluded; widen them for unusual
// lighting or skin tones, or pass a mask.
struct SkinModel {
  int y_min = 40, y_max = 255;
  int cr_min = 133, cr_max = 173;
  int cb_min = 77, cb_max = 127;
  bool Check() const;
};

struct PixelRect {
  int x = 0, y = 0, width = 0, height = 0;
  bool empty() const { return width <= 0 || height <= 0; }
};
// "x,y,w,h" -> rect; kInvalidArgument otherwise.
Result<PixelRect> ParsePixelRect(std::string_view text);

struct ImageEdgeOptions {
  QueryInputKind kind = QueryInputKind::kAuto;
  SkinModel skin;
  std::filesystem::path mask;  // photo: hand mask image (non-zero = hand), replaces skin colour
  PixelRect roi;               // photo: only this rectangle can hold the hand (empty: all)
  double canny_low = 40;       // Canny hysteresis thresholds (on the 5x5-blurred grey image)
  double canny_high = 120;
  // Canny edges inside the hand region only (the database's views have no background edges).
  // false: also those within `dilate_px` outside it (the behaviour before issue 16 item 3).
  bool interior_edges_only = true;
  int dilate_px = 4;
  // Canny edges this close to the silhouette (px, in the input picture) are dropped: Canny
  // finds the hand's outline too, a pixel or two from the contour, and the outline twice
  // weighs the silhouette double in D_c. 0: keep them.
  int contour_clearance_px = 2;
  int min_hand_pixels = 400;  // smaller largest regions mean "no hand found"
  // Label EXR: the converter's edge rule (edges/edges.h). Set these to the options the
  // database was converted with (its manifest records them; `handdb query` reads them) so a
  // label query is converted exactly like the database's views.
  EdgeOptions label_edges;
  JointPairs label_joint_pairs = DefaultJointPairs();
  bool Check() const;
};

struct EdgePixelXY {
  int32_t x = 0;  // column
  int32_t y = 0;  // row
};

struct QueryEdges {
  QueryInputKind kind = QueryInputKind::kAuto;  // the kind actually used
  int width = 0;                                // source image size
  int height = 0;
  std::vector<EdgePixelXY> edge_pixels;     // edges in source pixels (raster order)
  std::vector<EdgePixelXY> contour_pixels;  // the silhouette used for normalisation
  int64_t hand_pixels = 0;                  // photo/labels: pixels of the hand region
  bool touches_border = false;              // the hand region reaches the image border
  // Normalisation: normalised = (pixel centre - centre) * scale.
  double centre_x = 0, centre_y = 0, diameter_px = 0, scale = 0;
  std::vector<PointQ> points;              // normalised frame, sorted by (y, x), unique
  std::vector<Point2f> points_px() const;  // the same in px
  // The inverse map, normalised px -> source image px (pixel centres at integer + 0.5, the
  // origin at the top-left corner of the top-left pixel): where a match's keypoint (already in
  // the query's normalised frame: rolled, and mirrored back for a left hand) lies in the input.
  Point2f ImageFromNormalised(Point2f normalised) const {
    return {static_cast<float>(normalised.x / scale + centre_x),
            static_cast<float>(normalised.y / scale + centre_y)};
  }
};

// Errors, each naming the file: kNotFound, kBadImage (unreadable / wrong size mask / not an
// image), kNoHand (no hand region or fewer than two edge pixels), kInvalidArgument (bad ROI),
// and ReadLabelExr's errors for EXRs.
Result<QueryEdges> LoadQueryEdges(const std::filesystem::path& image,
                                  const ImageEdgeOptions& options);

}  // namespace handdb
