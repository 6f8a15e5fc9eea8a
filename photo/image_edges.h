// From a picture to a query: edge points in the database's normalised frame.
//
// Three kinds of input (docs/query.md):
//  - a photo (PNG/JPEG): the hand is found by skin colour (a documented, tunable YCrCb box), or
//    given by --mask (non-zero = hand), optionally restricted to --roi; the largest connected
//    region is the hand. The hand is then cropped and resampled to a fixed working size (its
//    diameter `work_diameter_px`), so the mask clean-up, the Canny blur and thresholds and the
//    wrist cut act the same on a 100 px thumbnail and a 12 Mpx phone photo; a visible forearm is
//    cut off at the wrist. Edges = the silhouette contour plus the Canny edges (OpenCV) inside
//    the hand region, except those within `contour_clearance_px` of the contour (one outline, as
//    in the database's views, not Canny's outline beside the contour's);
//  - an edge image (non-zero pixels are edges);
//  - a Blender label EXR (clean synthetic edges through the converter's own code:
//    edges/exr_io.h + edges/view_conversion.h, BorderContact::kAllow).
// Then exactly the database's normalisation (edges/normalise.h, the converter's code): the
// silhouette's diameter is scaled to 192 px and its centre rule applied, points quantised to
// PointQ. For edge images the silhouette is unknown and all edge pixels stand in for it (the
// outline is among them, so their convex hull, which is all the normalisation looks at, is the
// same).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "base/status.h"
#include "edges/edges.h"
#include "format/roll.h"
#include "format/view.h"
#include "photo/hand_landmarks.h"

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
  // Canny hysteresis thresholds, on the grey image blurred by OpenCV's 5x5 Gaussian, at the
  // working size below (scaled with it, so they hold for any working size).
  double canny_low = 40;
  double canny_high = 120;
  // Working size: the hand (the largest skin/mask region) is cropped with a margin and resampled
  // so its diameter is this many px before the mask clean-up (3x3 opening, 5x5 closing) and
  // Canny; kernel sizes, blur, thresholds and `dilate_px` / `contour_clearance_px` are those of a
  // hand `kReferenceHandDiameterPx` across and scale with the working size. 0: work at the
  // picture's own resolution. Measured on the
  // development photos (docs/evaluation.md): at their own size, 96/128/160 px and native are
  // within noise of each other (48.5-53% top-1); at 4x their size native falls to 35.5% and
  // 128 px keeps 49%. Smaller working sizes lose thin creases (a 1 px line at 150 px is gone at
  // 96), so the default is 128.
  double work_diameter_px = 128;
  // The forearm: a region that leaves the picture (or runs far) past the palm
  // is cut off along the line across it `wrist_cut_radii` palm radii from the palm centre (the
  // largest inscribed circle), at right angles to the way the arm leaves. The database's hand
  // ends ~1.8 radii from its palm centre (its short wrist stub); 2.6 cuts only arms clearly
  // longer than that. The arm is the widest run of the region along the picture's border if it
  // is at least 0.8 palm radii long; narrower runs are fingers leaving the picture (and the
  // picture is refused as a cut hand), unless the region seen through a strip half a palm radius
  // deep along the border has an arm's run and is not refused (a band across the forearm breaks
  // the region's own run). Failure case: four fingers held together that leave the picture look
  // like an arm. false: keep the whole region.
  bool cut_forearm = true;
  double wrist_cut_radii = 2.6;
  // Canny edges inside the hand region only (the database's views have no background edges).
  // false: also those within `dilate_px` outside it.
  bool interior_edges_only = true;
  int dilate_px = 4;
  // Canny edges this close to the silhouette (px, in the input picture) are dropped: Canny
  // finds the hand's outline too, a pixel or two from the contour, and the outline twice
  // weighs the silhouette double in D_c. 0: keep them.
  int contour_clearance_px = 2;
  int min_hand_pixels = 400;  // smaller largest regions (picture px) mean "no hand found"
  // A second skin region at least this share of the largest (and min_hand_pixels) means two
  // hands, or a hand and a face: refused (crop the picture or give --roi / --mask). 0: never.
  double second_region_share = 0.5;
  // The hand may leave the picture in one place (the arm, along at most 2.5 palm radii of the
  // border); where it touches the border elsewhere, or the arm's stretch goes on round a corner,
  // for more than this share of its diameter (fingers or a side cut off), the picture is refused.
  double max_cut_share = 0.25;
  // Label EXR: the converter's edge rule (edges/edges.h). Set these to the options the
  // database was converted with (its manifest records them; `handdb query` reads them) so a
  // label query is converted exactly like the database's views.
  EdgeOptions label_edges;
  JointPairs label_joint_pairs = DefaultJointPairs();
  bool Check() const;
};

// The hand diameter (px) at which the photo path's pixel-sized defaults are set: 3x3 opening,
// 5x5 closing, OpenCV's 5x5 Gaussian before Canny, 2 px contour clearance (the development
// photos, 100 x 100 px JPEGs of hands ~96 px across, were the reference).
constexpr double kReferenceHandDiameterPx = 96;

// What a picture may hold (docs/conventions.md, "Limits"); past them it is refused in one line
// naming it (kInvalidArgument).
// Edge points of a query after normalisation (one per 1/16 px at most). The search keeps each
// point once per roll and hand (~20 bytes each, ~0.6 KB a point with 16 rolls), so this bounds a
// search's memory; a hand's outline and creases give a few thousand.
constexpr size_t kMaxQueryPoints = 65536;
// Non-zero pixels of an edge image, counted before any list of them is made: edges are lines,
// and an 8192 px hand drawn with 3 px lines has ~100,000.
constexpr int kMaxEdgeImagePixels = 1 << 20;
// Sides of a photo: the clean-up, the crop and Canny need room, and a picture a few px high or
// wide (a 2000 x 1 strip) holds no hand.
constexpr int kMinPhotoSide = 16;

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
  // Photo: what the working size and the wrist cut did (for --json and the contact sheet).
  double work_scale = 1;     // working px per source px (1: the picture's own resolution)
  bool forearm_cut = false;  // a forearm was cut off
  // An arm leaves the picture (whether or not it was long enough to cut): the unit direction,
  // in source px (y down), from the palm centre towards where it leaves. Not looked for when
  // cut_forearm is off; (0, 0) when not found.
  bool arm_found = false;
  double arm_dir_x = 0, arm_dir_y = 0;
  double palm_centre_x = 0;  // the palm's inscribed circle, source px (0 radius: not found)
  double palm_centre_y = 0;
  double palm_radius_px = 0;
  std::array<double, 4> wrist_line{};  // the cut: x0, y0, x1, y1 in source px (when forearm_cut)
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

// The presence at which the network's joints in a tracked crop (PictureOptions::landmark_start)
// are kept: MediaPipe Hands' own tracking threshold.
constexpr float kTrackedCropPresence = 0.5f;

// How a picture becomes evidence: its edges and, for a photo, the hand landmark network
// (photo/hand_landmarks.h), which runs beside the edge extraction on the same decoded pixels.
struct PictureOptions {
  ImageEdgeOptions edges;
  // Run on a photo's segmented hand; its joints re-rank the search's nearest views
  // (pose/landmark_rank.h). Null: none. Edge images and label EXRs never get landmarks.
  std::shared_ptr<const HandLandmarker> landmarker;
  // How often the network runs: 1, on the crop the segmentation gives; 2, then again on the crop
  // its joints give (MediaPipe's tracking crop, hand_landmarks.h), whose joints are the answer.
  // The second run costs one more network run a photo (~7 ms on one core) and brings the fitted
  // pose nearer the truth (docs/decisions/0027).
  int landmark_passes = 2;
  // A video's frame: the crop around the previous frame's joints (CropAroundLandmarks), where
  // the network runs once, as MediaPipe Hands tracks a hand; when its presence there is below
  // kTrackedCropPresence, the frame starts over from the segmentation's crop. None: a picture
  // alone.
  std::optional<LandmarkCrop> landmark_start;
  bool Check() const;
};

// What a picture says about the hand in it.
struct PictureEvidence {
  PictureEvidence() = default;
  explicit PictureEvidence(QueryEdges e) : edges(std::move(e)) {}
  QueryEdges edges;
  // A photo read with PictureOptions::landmarker: the network's joints, in source px, found in
  // the crop the segmentation gave (the silhouette's centre, 1.5 diameters wide, turned so the
  // hand points up) or, with two passes, in the crop those joints gave (hand_landmarks.h).
  std::optional<HandLandmarks> landmarks;
};

// Decodes the picture once and returns its evidence: LoadQueryEdges' edges (bit for bit the
// same), then the landmarks. Errors as LoadQueryEdges'.
Result<PictureEvidence> ReadPicture(const std::filesystem::path& image,
                                    const PictureOptions& options);

// A picture already decoded in memory (a video's frame), as ReadImage decodes a file: 8-bit,
// `channels` 1 (grey), 3 (BGR) or 4 (BGRA), rows `row_bytes` apart (0: width * channels).
struct PicturePixels {
  int width = 0;
  int height = 0;
  int channels = 3;
  const uint8_t* data = nullptr;
  size_t row_bytes = 0;
};

// ReadPicture of decoded pixels: the same evidence, bit for bit, as ReadPicture of a PNG holding
// these pixels (options.edges.kind kAuto, kPhoto or kEdges; a mask is read from its file).
// `name` names the picture in errors. Errors: kBadImage (no pixels, too many, a channel count
// other than 1, 3, 4), kInvalidArgument (kLabels, bad options), then ReadPicture's.
Result<PictureEvidence> ReadPicturePixels(const std::string& name,
                                          const PicturePixels& pixels,
                                          const PictureOptions& options);

}  // namespace handdb
