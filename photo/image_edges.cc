#include "photo/image_edges.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "base/image_file.h"
#include "edges/edges.h"
#include "edges/exr_io.h"
#include "edges/normalise.h"
#include "edges/view_conversion.h"
#include "photo/image_read.h"

namespace handdb {
namespace {

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

Status CheckEnoughPixels(const std::string& what,
                         const std::vector<EdgePixel>& edges,
                         const std::vector<EdgePixel>& contour) {
  if (edges.size() < 2 || contour.size() < 2) {
    return Status(StatusCode::kNoHand,
                  what + ": no hand found (" + std::to_string(edges.size()) + " edge pixels)");
  }
  return Status::Ok();
}

// Fills `out` from the edge pixels, the contour that defined `norm` and the normalised points.
Status Fill(const std::string& what,
            const std::vector<EdgePixel>& edges,
            const std::vector<EdgePixel>& contour,
            const Normalisation& norm,
            std::vector<PointQ> points,
            QueryEdges* out) {
  if (norm.diameter < 8) {
    return Status(
        StatusCode::kNoHand,
        what + ": no hand found (the edges span only " + std::to_string(norm.diameter) + " px)");
  }
  // Every kind of picture passes here: the one place the points that size a search are bounded.
  if (points.size() > kMaxQueryPoints) {
    return Status(StatusCode::kInvalidArgument,
                  what + ": " + std::to_string(points.size()) + " edge points, more than the " +
                      std::to_string(kMaxQueryPoints) +
                      " a query may have (a hand's outline and creases have a few thousand)");
  }
  out->centre_x = norm.centre_x;
  out->centre_y = norm.centre_y;
  out->diameter_px = norm.diameter;
  out->scale = norm.scale;
  out->points = std::move(points);
  out->edge_pixels.clear();
  for (const EdgePixel& p : edges) out->edge_pixels.push_back({p.col, p.row});
  out->contour_pixels.clear();
  for (const EdgePixel& p : contour) out->contour_pixels.push_back({p.col, p.row});
  return Status::Ok();
}

// Fills contour (via the converter's silhouette rule), normalisation and points from the edge
// pixels; `contour` holds the silhouette pixels that define the normalisation.
Status Finish(const std::string& what,
              const std::vector<EdgePixel>& edges,
              const std::vector<EdgePixel>& contour,
              QueryEdges* out) {
  HANDDB_RETURN_IF_ERROR(CheckEnoughPixels(what, edges, contour));
  Result<Normalisation> norm = ComputeNormalisation(contour);
  if (!norm.ok()) return Status(norm.status().code(), what + ": " + norm.status().message());
  return Fill(what, edges, contour, *norm, NormalisePixels(edges, *norm), out);
}

std::vector<EdgePixel> NonZeroPixels(const cv::Mat& m) {
  std::vector<EdgePixel> out;
  for (int y = 0; y < m.rows; ++y) {
    const uint8_t* row = m.ptr<uint8_t>(y);
    for (int x = 0; x < m.cols; ++x) {
      if (row[x] != 0) out.push_back({x, y});
    }
  }
  return out;
}

// An image that is one channel (or equal channels) with at most two distinct values, a dark
// majority and some non-zero pixels looks like an edge image.
bool LooksLikeEdgeImage(const cv::Mat& any) {
  cv::Mat grey;
  if (any.channels() == 1) {
    grey = any;
  } else {
    std::vector<cv::Mat> ch;
    cv::split(any, ch);
    for (size_t c = 1; c < std::min<size_t>(ch.size(), 3); ++c) {
      if (cv::countNonZero(ch[c] != ch[0]) != 0) return false;
    }
    grey = ch[0];
  }
  if (grey.depth() != CV_8U) return false;
  int hist[256] = {0};
  for (int y = 0; y < grey.rows; ++y) {
    const uint8_t* row = grey.ptr<uint8_t>(y);
    for (int x = 0; x < grey.cols; ++x) ++hist[row[x]];
  }
  int distinct = 0;
  for (int h : hist) distinct += h > 0;
  const double nonzero = 1.0 - static_cast<double>(hist[0]) / (static_cast<double>(grey.total()));
  return distinct <= 2 && nonzero > 0 && nonzero < 0.5;
}

Result<QueryEdges> FromEdgeImage(const std::filesystem::path& path, const cv::Mat& any) {
  QueryEdges out;
  out.kind = QueryInputKind::kEdges;
  out.width = any.cols;
  out.height = any.rows;
  cv::Mat nonzero;
  if (any.channels() == 1) {
    nonzero = any != 0;
  } else {
    std::vector<cv::Mat> ch;
    cv::split(any, ch);
    nonzero = ch[0] != 0;
    for (size_t c = 1; c < std::min<size_t>(ch.size(), 3); ++c) nonzero |= ch[c] != 0;
  }
  // Counted before they are listed: a filled area given as an edge image (--input edges) would
  // otherwise cost its lists before the points are refused.
  if (const int on = cv::countNonZero(nonzero); on > kMaxEdgeImagePixels) {
    return Status(StatusCode::kInvalidArgument,
                  path.string() + ": " + std::to_string(on) + " edge pixels, more than the " +
                      std::to_string(kMaxEdgeImagePixels) +
                      " an edge image may have (edges are lines, not filled areas)");
  }
  const std::vector<EdgePixel> edges = NonZeroPixels(nonzero);
  HANDDB_RETURN_IF_ERROR(Finish(path.string(), edges, edges, &out));
  return out;
}

// Through the converter's own path (edges/view_conversion.h), a cropped hand allowed.
Result<QueryEdges> FromLabels(const std::filesystem::path& path, const ImageEdgeOptions& options) {
  ExrReadOptions exr;
  exr.require_depth = false;
  Result<LabelImage> image = ReadLabelExr(path, exr);
  if (!image.ok()) return image.status();
  ViewConversionOptions conversion;
  conversion.edges = options.label_edges;
  conversion.joint_pairs = options.label_joint_pairs;
  const std::string what = path.string();
  auto converted = LabelImageToPoints(*image, conversion, BorderContact::kAllow, what);
  if (!converted.ok()) return converted.status();
  const EdgeResult& edges = converted->edges;
  QueryEdges out;
  out.kind = QueryInputKind::kLabels;
  out.width = image->width;
  out.height = image->height;
  out.hand_pixels = edges.num_hand_pixels;
  out.touches_border = edges.touches_border;
  HANDDB_RETURN_IF_ERROR(CheckEnoughPixels(what, edges.edges, edges.silhouette));
  HANDDB_RETURN_IF_ERROR(Fill(what,
                              edges.edges,
                              edges.silhouette,
                              converted->normalisation,
                              std::move(converted->points),
                              &out));
  return out;
}

cv::Mat Ellipse(double size) {
  int k = std::max(1, static_cast<int>(std::lround(size)));
  if (k % 2 == 0) ++k;
  return cv::getStructuringElement(cv::MORPH_ELLIPSE, {k, k});
}

// A colour image whose three channels are equal everywhere has no skin colour to find.
bool IsGrey(const cv::Mat& bgr) {
  std::vector<cv::Mat> ch;
  cv::split(bgr, ch);
  return cv::countNonZero(ch[0] != ch[1]) == 0 && cv::countNonZero(ch[0] != ch[2]) == 0;
}

cv::Mat SkinMask(const cv::Mat& bgr, const SkinModel& s) {
  cv::Mat ycrcb, out;
  cv::cvtColor(bgr, ycrcb, cv::COLOR_BGR2YCrCb);
  cv::inRange(
      ycrcb, cv::Scalar(s.y_min, s.cr_min, s.cb_min), cv::Scalar(s.y_max, s.cr_max, s.cb_max), out);
  return out;
}

// Speckle removed, small gaps closed: a 3x3 opening and a 5x5 closing at the reference hand
// size, scaled by `s`.
void CleanMask(cv::Mat* mask, double s) {
  cv::morphologyEx(*mask, *mask, cv::MORPH_OPEN, Ellipse(3 * s));
  cv::morphologyEx(*mask, *mask, cv::MORPH_CLOSE, Ellipse(5 * s));
}

struct Regions {
  cv::Mat labels;
  int largest = 0;  // label of the largest region (0: none)
  int largest_area = 0;
  int second_area = 0;
  cv::Rect largest_box;
};

Regions LargestRegions(const cv::Mat& mask) {
  Regions r;
  cv::Mat stats, centroids;
  const int n = cv::connectedComponentsWithStats(mask, r.labels, stats, centroids, 8, CV_32S);
  for (int i = 1; i < n; ++i) {
    const int area = stats.at<int>(i, cv::CC_STAT_AREA);
    if (area > r.largest_area) {
      r.second_area = r.largest_area;
      r.largest_area = area;
      r.largest = i;
    } else {
      r.second_area = std::max(r.second_area, area);
    }
  }
  if (r.largest > 0) {
    r.largest_box = cv::Rect(stats.at<int>(r.largest, cv::CC_STAT_LEFT),
                             stats.at<int>(r.largest, cv::CC_STAT_TOP),
                             stats.at<int>(r.largest, cv::CC_STAT_WIDTH),
                             stats.at<int>(r.largest, cv::CC_STAT_HEIGHT));
  }
  return r;
}

// The largest distance between two pixel centres of the region (its convex hull's diameter).
double RegionDiameter(const cv::Mat& region) {
  std::vector<cv::Point> pts;
  cv::findNonZero(region, pts);
  if (pts.size() < 2) return 0;
  std::vector<cv::Point> hull;
  cv::convexHull(pts, hull);
  double best = 0;
  for (size_t i = 0; i < hull.size(); ++i) {
    for (size_t j = i + 1; j < hull.size(); ++j) {
      best =
          std::max(best, std::hypot(double(hull[i].x - hull[j].x), double(hull[i].y - hull[j].y)));
    }
  }
  return best;
}

struct BorderRun {
  int length = 0;        // px along the border, bridged gaps included
  int contact = 0;       // of them, px where the contact mask is set
  cv::Point2d centroid;  // of those contact px (pixel centres at +0.5)
};

// Runs of the region's pixels along the picture's border, walked once around it (top left to
// right, right side down, bottom right to left, left side up); runs separated by fewer than
// `gap` background pixels are one run (a dark band across a forearm, a strap). A run's centroid
// and contact count are those of its pixels set in `contact` (the region itself, or the region
// a border reach was taken of).
std::vector<BorderRun> BorderRuns(const cv::Mat& region, int gap, const cv::Mat& contact) {
  const int w = region.cols;
  const int h = region.rows;
  std::vector<cv::Point> ring;
  for (int x = 0; x < w; ++x) ring.emplace_back(x, 0);
  for (int y = 1; y < h; ++y) ring.emplace_back(w - 1, y);
  for (int x = w - 2; x >= 0 && h > 1; --x) ring.emplace_back(x, h - 1);
  for (int y = h - 2; y >= 1 && w > 1; --y) ring.emplace_back(0, y);
  const int n = static_cast<int>(ring.size());
  const auto on = [&](int i) { return region.at<uint8_t>(ring[i % n]) != 0; };
  int start = -1;  // a background pixel to start from (none: the region surrounds the picture)
  for (int i = 0; i < n; ++i) {
    if (!on(i)) {
      start = i;
      break;
    }
  }
  std::vector<BorderRun> runs;
  BorderRun run;
  int bg = 0;
  const auto close_run = [&] {
    if (run.length > 0) {
      run.centroid /= std::max(1, run.contact);
      runs.push_back(run);
    }
    run = {};
  };
  const auto add = [&](int i) {
    ++run.length;
    if (contact.at<uint8_t>(ring[i]) == 0) return;
    ++run.contact;
    run.centroid += cv::Point2d(ring[i].x + 0.5, ring[i].y + 0.5);
  };
  if (start < 0) {
    for (int i = 0; i < n; ++i) add(i);
    close_run();
    return runs;
  }
  for (int k = 1; k <= n; ++k) {
    const int i = (start + k) % n;
    if (on(i)) {
      if (run.length > 0 && bg > 0 && bg < gap) {
        run.length += bg;  // bridge a short gap
      } else if (run.length > 0 && bg > 0) {
        close_run();
      }
      bg = 0;
      add(i);
    } else if (run.length > 0) {
      ++bg;
    }
  }
  close_run();
  return runs;
}

std::vector<BorderRun> BorderRuns(const cv::Mat& region, int gap) {
  return BorderRuns(region, gap, region);
}

// The region seen from the picture's border through a strip `depth` px deep: a border pixel is
// set when the region has a pixel within `depth` of it, straight inwards.
cv::Mat BorderReach(const cv::Mat& region, int depth) {
  const int w = region.cols;
  const int h = region.rows;
  cv::Mat reach = cv::Mat::zeros(h, w, CV_8U);
  const int dy = std::clamp(depth, 1, h);
  const int dx = std::clamp(depth, 1, w);
  const auto any = [&](cv::Rect r) { return cv::countNonZero(region(r)) > 0 ? 255 : 0; };
  for (int x = 0; x < w; ++x) {
    reach.at<uint8_t>(0, x) |= any({x, 0, 1, dy});
    reach.at<uint8_t>(h - 1, x) |= any({x, h - dy, 1, dy});
  }
  for (int y = 0; y < h; ++y) {
    reach.at<uint8_t>(y, 0) |= any({0, y, dx, 1});
    reach.at<uint8_t>(y, w - 1) |= any({w - dx, y, dx, 1});
  }
  return reach;
}

struct WristCut {
  bool arm = false;  // an arm leaves the picture (a border run at least kArmRadii palm radii)
  bool cut = false;  // and part of it was cut off
  cv::Point2d palm_centre;  // working px (pixel centres at +0.5)
  double palm_radius = 0;
  cv::Point2d a, b;  // the cut line's ends across the region, working px
  cv::Point2d dir;   // unit direction from the palm centre to the arm (working px), when arm
};

// A wrist is 1.2-2 palm radii wide (a fist has the largest radius); one finger is about half a
// radius to one radius (fingers leaving the picture side by side are separate runs).
constexpr double kArmRadii = 0.8;
// How deep a strip along the border the arm's run is seen through, in palm radii, when the
// region's own runs hold no arm and the hand would be refused as cut by the border. A bracelet, a
// strap or a watch band across the forearm where it leaves the picture (or a speckled skin edge
// there) breaks the region's own run along the border into pieces too short for an arm, but the
// arm lies just inside them; the notch between two fingers that leave the picture is deeper than
// half a palm radius, so their runs stay apart.
constexpr double kArmReachRadii = 0.5;
// Where it leaves the picture after the wrist cut, an arm's run along the border is at most 2.15
// palm radii on the 200 development photos and 2.04 on 745 photo-like renders with a forearm;
// the rest of a longer run is hand cut by the border.
constexpr double kArmRunRadii = 2.5;

// The palm is the region's largest inscribed circle (distance-transform maximum; the picture's
// border counts as background, so an arm running out of the picture does not look wide). The arm
// is the region's widest run along the picture's border, if it is at least kArmRadii palm radii
// long (fingers that leave the picture are narrower, and are not an arm); with `reach_radii` > 0
// the runs are those of the region seen through a strip that many palm radii deep along the
// border (BorderReach), each counted only where the region itself touches the border. The arm
// leaves in the direction from the palm centre to the centroid of the region's own border pixels
// in its run. Everything farther than `radii` palm radii from the palm centre along that
// direction is the forearm and is removed. A region that does not touch the border, or only with
// narrow runs, is left alone.
WristCut CutForearm(cv::Mat* region, double radii, double reach_radii) {
  WristCut out;
  cv::Mat padded;
  cv::copyMakeBorder(*region, padded, 1, 1, 1, 1, cv::BORDER_CONSTANT, 0);
  cv::Mat dt;
  cv::distanceTransform(padded, dt, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  double max_dt = 0;
  cv::Point at;
  cv::minMaxLoc(dt, nullptr, &max_dt, nullptr, &at);
  if (max_dt <= 0) return out;
  out.palm_centre = {at.x - 1 + 0.5, at.y - 1 + 0.5};
  out.palm_radius = max_dt;
  const int w = region->cols;
  const int h = region->rows;
  std::vector<BorderRun> runs;
  if (reach_radii > 0) {
    const int depth = std::max(1, static_cast<int>(std::lround(reach_radii * out.palm_radius)));
    runs = BorderRuns(BorderReach(*region, depth), 1, *region);
    // Only the region's own border contact leaves the picture: a run that merely comes near it
    // is no arm.
    std::erase_if(runs, [](const BorderRun& r) { return r.contact == 0; });
  } else {
    runs = BorderRuns(*region, 1);
  }
  const auto widest =
      std::max_element(runs.begin(), runs.end(), [](const BorderRun& a, const BorderRun& b) {
        return a.length < b.length;
      });
  if (widest == runs.end() || widest->length < kArmRadii * out.palm_radius) return out;
  out.arm = true;
  cv::Point2d dir = widest->centroid - out.palm_centre;
  const double len = std::hypot(dir.x, dir.y);
  if (len < 1e-9) return out;
  dir /= len;
  out.dir = dir;
  const double limit = radii * out.palm_radius;
  double lo = 1e30, hi = -1e30;  // extent of the cut line across the region
  for (int y = 0; y < h; ++y) {
    uint8_t* row = region->ptr<uint8_t>(y);
    for (int x = 0; x < w; ++x) {
      if (!row[x]) continue;
      const double px = x + 0.5 - out.palm_centre.x, py = y + 0.5 - out.palm_centre.y;
      if (px * dir.x + py * dir.y > limit) {
        row[x] = 0;
        out.cut = true;
        const double across = -px * dir.y + py * dir.x;
        lo = std::min(lo, across);
        hi = std::max(hi, across);
      }
    }
  }
  if (out.cut) {
    const cv::Point2d base = out.palm_centre + dir * limit;
    const cv::Point2d perp(-dir.y, dir.x);
    out.a = base + perp * lo;
    out.b = base + perp * hi;
  }
  return out;
}

// What a photo's landmark step needs: the network (null: no landmarks), how often it runs and,
// for a video, where its first run looks (PictureOptions).
struct LandmarkStep {
  const HandLandmarker* landmarker = nullptr;
  int passes = 2;
  std::optional<LandmarkCrop> start;
};

bool UsableCrop(const LandmarkCrop& c) {
  return std::isfinite(c.centre.x) && std::isfinite(c.centre.y) && std::isfinite(c.angle_deg) &&
         c.side >= 4 && c.side < 1e6f;
}

LandmarkStep StepOf(const PictureOptions& options) {
  return {options.landmarker.get(), options.landmark_passes, options.landmark_start};
}

// The landmark network on the hand the photo path found (hand_landmarks.h). The first crop is
// square, centred on the silhouette, 1.5 of its diameters wide (the whole hand with a margin),
// turned so the hand points up: away from the forearm where one leaves the picture, else from
// the palm centre towards the silhouette's centre (the fingers reach further from the palm than
// the wrist does); in 195 of the 199 development photos the turn comes from the arm. With
// `passes` 2 the network runs again on the crop its first joints give (CropAroundLandmarks, the
// crop MediaPipe Hands tracks a hand in) and the second run's joints are the answer: the hand
// then sits in the crop as in the network's training (docs/decisions/0027). With a start crop
// (a video's previous frame's) the network runs there once; below kTrackedCropPresence the
// frame starts over from the silhouette.
HandLandmarks FindLandmarks(const LandmarkStep& step, const cv::Mat& bgr, const QueryEdges& q) {
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  auto detect = [&](const LandmarkCrop& c) {
    return step.landmarker->Detect(rgb.data, rgb.cols, rgb.rows, rgb.step, c);
  };
  if (step.start && UsableCrop(*step.start)) {
    HandLandmarks tracked = detect(*step.start);
    if (tracked.presence >= kTrackedCropPresence) return tracked;
  }
  double up_x = 0, up_y = -1;
  if (q.arm_found) {
    up_x = -q.arm_dir_x;
    up_y = -q.arm_dir_y;
  } else if (q.palm_radius_px > 0) {
    const double dx = q.centre_x - q.palm_centre_x, dy = q.centre_y - q.palm_centre_y;
    if (std::hypot(dx, dy) > 1e-6) {
      up_x = dx;
      up_y = dy;
    }
  }
  LandmarkCrop crop;
  crop.centre = {static_cast<float>(q.centre_x), static_cast<float>(q.centre_y)};
  crop.side = static_cast<float>(1.5 * q.diameter_px);
  crop.angle_deg = static_cast<float>(std::atan2(up_x, -up_y) * 180.0 / M_PI);
  HandLandmarks found = detect(crop);
  for (int pass = 1; pass < step.passes; ++pass) {
    crop = CropAroundLandmarks(found);
    // Joints that give no crop (not finite, or all in one place) keep the run before.
    if (!UsableCrop(crop)) break;
    found = detect(crop);
  }
  return found;
}

// The photo path's 8-bit BGR picture, whatever the file's depth and channels.
cv::Mat ToBgr8(const cv::Mat& any) {
  cv::Mat bgr;
  if (any.depth() != CV_8U) {
    any.convertTo(bgr, CV_8U, any.depth() == CV_16U ? 1.0 / 257.0 : 255.0);
  } else {
    bgr = any;
  }
  if (bgr.channels() == 1) cv::cvtColor(bgr, bgr, cv::COLOR_GRAY2BGR);
  if (bgr.channels() == 4) cv::cvtColor(bgr, bgr, cv::COLOR_BGRA2BGR);
  return bgr;
}

// Step 1: hand candidates at the picture's resolution: the mask (non-zero = hand) or skin colour.
// `source` is the picture's size in its file (a mask has that size and is reduced like the
// picture when a huge JPEG was decoded reduced).
Result<cv::Mat> HandCandidates(const std::string& what,
                               const cv::Mat& bgr,
                               cv::Size source,
                               const ImageEdgeOptions& options) {
  if (options.mask.empty()) {
    if (IsGrey(bgr)) {
      return Status(StatusCode::kNoHand,
                    what + ": a grey image (" + std::to_string(source.width) + "x" +
                        std::to_string(source.height) +
                        ") has no skin colour to find the hand by; give its region with --mask");
    }
    return SkinMask(bgr, options.skin);
  }
  std::error_code ec;
  if (!std::filesystem::exists(options.mask, ec)) {
    return Status(StatusCode::kNotFound, options.mask.string() + ": no such mask file");
  }
  cv::Mat m = ReadImage(options.mask, cv::IMREAD_GRAYSCALE).value_or(cv::Mat());
  if (!m.empty() && m.size() == source && source != bgr.size()) {
    cv::resize(m, m, bgr.size(), 0, 0, cv::INTER_AREA);
  }
  if (m.empty()) {
    return Status(StatusCode::kBadImage, options.mask.string() + ": cannot read the mask image");
  }
  if (m.cols != bgr.cols || m.rows != bgr.rows) {
    return Status(StatusCode::kBadImage,
                  options.mask.string() + ": mask is " + std::to_string(m.cols) + "x" +
                      std::to_string(m.rows) + ", the image " + std::to_string(source.width) + "x" +
                      std::to_string(source.height));
  }
  return cv::Mat(m != 0);
}

// Where the hand may be: the ROI as a mask (empty: anywhere).
Result<cv::Mat> RoiMask(const std::string& what, const PixelRect& r, int w, int h) {
  if (r.empty()) return cv::Mat();
  if (r.x < 0 || r.y < 0 || r.x + r.width > w || r.y + r.height > h) {
    return Status(StatusCode::kInvalidArgument,
                  what + ": ROI " + std::to_string(r.x) + "," + std::to_string(r.y) + "," +
                      std::to_string(r.width) + "," + std::to_string(r.height) +
                      " is not inside the " + std::to_string(w) + "x" + std::to_string(h) +
                      " image");
  }
  cv::Mat keep = cv::Mat::zeros(h, w, CV_8U);
  keep(cv::Rect(r.x, r.y, r.width, r.height)).setTo(255);
  return keep;
}

struct FoundHand {
  Regions regions;         // of the copy the hand was found on
  double find_scale = 1;   // that copy's px per picture px
  double diameter_px = 0;  // the hand's diameter, picture px
};

// Step 2: the hand is the largest 8-connected region, found on a copy at most kFindSide px
// across (a 12 Mpx photo needs no more to be found, and the clean-up costs little there).
// Refused: too small a region, or a second one nearly as large (two hands, a hand and a face).
Result<FoundHand> FindHand(const std::string& what,
                           const cv::Mat& cand,
                           const cv::Mat& keep,
                           bool use_mask,
                           const ImageEdgeOptions& options) {
  constexpr int kFindSide = 512;
  FoundHand out;
  out.find_scale = std::min(1.0, double(kFindSide) / std::max(cand.cols, cand.rows));
  cv::Mat small = cand;
  if (!keep.empty()) small = cand & keep;
  if (out.find_scale < 1) {
    // A long thin picture would round its short side to no pixels: one at least.
    const int cols = cvRound(cand.cols * out.find_scale),
              rows = cvRound(cand.rows * out.find_scale);
    if (cols > 0 && rows > 0) {
      cv::resize(small, small, cv::Size(), out.find_scale, out.find_scale, cv::INTER_AREA);
    } else {
      cv::resize(small, small, {std::max(1, cols), std::max(1, rows)}, 0, 0, cv::INTER_AREA);
    }
    small = small > 127;
  }
  if (!use_mask) CleanMask(&small, 1.0);
  out.regions = LargestRegions(small);
  const Regions& found = out.regions;
  const double px_per_found = 1.0 / (out.find_scale * out.find_scale);  // picture px per found px
  const auto area_px = [&](int area) {
    return static_cast<int64_t>(std::llround(area * px_per_found));
  };
  const std::string kind = use_mask ? "mask" : "skin-coloured";
  if (area_px(found.largest_area) < options.min_hand_pixels) {
    return Status(StatusCode::kNoHand,
                  what + ": no hand found (largest " + kind + " region has " +
                      std::to_string(area_px(found.largest_area)) + " pixels, need " +
                      std::to_string(options.min_hand_pixels) + ")");
  }
  if (options.second_region_share > 0 && area_px(found.second_area) >= options.min_hand_pixels &&
      found.second_area >= options.second_region_share * found.largest_area) {
    return Status(StatusCode::kNoHand,
                  what + ": two hand-sized " + kind + " regions (" +
                      std::to_string(area_px(found.largest_area)) + " and " +
                      std::to_string(area_px(found.second_area)) +
                      " pixels): crop the picture to one hand, or give --roi or --mask");
  }
  out.diameter_px = RegionDiameter(found.labels == found.largest) / out.find_scale;
  return out;
}

// The hand at the working size: a crop of the picture resampled, and the hand's region in it.
struct WorkingHand {
  cv::Rect crop;  // of the picture
  double fx = 1;  // working px per picture px, the exact factors of the resize
  double fy = 1;
  double s = 1;      // working size / kReferenceHandDiameterPx: scales the pixel-sized options
  double scale = 1;  // the scale asked for: working diameter / the found hand's diameter
  cv::Mat bgr;       // the crop, resampled
  cv::Mat hand;      // the hand's region (255) in it
};

// Step 3: crop around the hand (a margin of a fifth of its diameter, for the clean-up and
// Canny), resample it to the working size, and take the largest region there again.
Result<WorkingHand> CropToWorkingSize(const std::string& what,
                                      const cv::Mat& bgr,
                                      const cv::Mat& cand,
                                      const cv::Mat& keep,
                                      bool use_mask,
                                      const FoundHand& found,
                                      const ImageEdgeOptions& options) {
  const int w = bgr.cols;
  const int h = bgr.rows;
  WorkingHand out;
  out.scale = options.work_diameter_px > 0 && found.diameter_px > 0
                  ? options.work_diameter_px / found.diameter_px
                  : 1.0;
  const double work_scale = out.scale;
  out.s = options.work_diameter_px > 0 ? options.work_diameter_px / kReferenceHandDiameterPx : 1.0;
  out.crop = cv::Rect(0, 0, w, h);
  if (options.work_diameter_px > 0) {
    const double margin = 0.2 * found.diameter_px + 4;
    const cv::Rect b = found.regions.largest_box;
    const double f = found.find_scale;
    const int x0 = std::max(0, static_cast<int>(std::floor(b.x / f - margin)));
    const int y0 = std::max(0, static_cast<int>(std::floor(b.y / f - margin)));
    const int x1 = std::min(w, static_cast<int>(std::ceil((b.x + b.width) / f + margin)));
    const int y1 = std::min(h, static_cast<int>(std::ceil((b.y + b.height) / f + margin)));
    out.crop = cv::Rect(x0, y0, std::max(1, x1 - x0), std::max(1, y1 - y0));
  }
  const cv::Rect& crop = out.crop;
  cv::Mat work_bgr = bgr(crop);
  cv::Mat work_cand = cand(crop);
  if (!keep.empty()) work_cand = work_cand & keep(crop);
  const cv::Size work_size(std::max(1, static_cast<int>(std::lround(crop.width * work_scale))),
                           std::max(1, static_cast<int>(std::lround(crop.height * work_scale))));
  out.fx = double(work_size.width) / crop.width;
  out.fy = double(work_size.height) / crop.height;
  if (work_size != crop.size()) {
    cv::resize(work_bgr, work_bgr, work_size, 0, 0, out.fx > 1 ? cv::INTER_CUBIC : cv::INTER_AREA);
    if (use_mask) {
      cv::resize(work_cand, work_cand, work_size, 0, 0, cv::INTER_AREA);
      work_cand = work_cand > 127;
    } else {
      // Skin colour of the resampled picture (not a resampled mask): the same rule at any size.
      work_cand = SkinMask(work_bgr, options.skin);
      if (!keep.empty()) {
        cv::Mat k;
        cv::resize(keep(crop), k, work_size, 0, 0, cv::INTER_NEAREST);
        work_cand &= k;
      }
    }
  }
  if (!use_mask) CleanMask(&work_cand, out.s);
  const Regions work_regions = LargestRegions(work_cand);
  if (work_regions.largest == 0) {
    return Status(StatusCode::kNoHand, what + ": no hand found after resampling it");
  }
  out.bgr = work_bgr;
  out.hand = work_regions.labels == work_regions.largest;
  return out;
}

// Step 4a: the hand, not the arm (CutForearm, its runs seen `reach_radii` deep), keeping the
// largest piece left.
WristCut CutArm(const ImageEdgeOptions& options, double reach_radii, cv::Mat* hand) {
  WristCut wrist;
  if (!options.cut_forearm) return wrist;
  wrist = CutForearm(hand, options.wrist_cut_radii, reach_radii);
  if (wrist.cut) {
    const Regions kept = LargestRegions(*hand);
    *hand = kept.labels == kept.largest;
  }
  return wrist;
}

// Step 4b: a hand that touches the picture's border away from the arm has lost part of itself
// there (with no arm found, every run counts: fingers leave the picture). `picture` is the
// picture's size.
Status CheckNotCutByBorder(const std::string& what,
                           const WorkingHand& work,
                           cv::Size picture,
                           const WristCut& wrist,
                           const ImageEdgeOptions& options) {
  const cv::Mat& hand = work.hand;
  const cv::Rect& crop = work.crop;
  const int ww = hand.cols;
  const int wh = hand.rows;
  cv::Mat on_picture_border = cv::Mat::zeros(wh, ww, CV_8U);
  // Only crop sides that are the picture's own sides count.
  if (crop.y == 0) hand.row(0).copyTo(on_picture_border.row(0));
  if (crop.y + crop.height == picture.height)
    hand.row(wh - 1).copyTo(on_picture_border.row(wh - 1));
  if (crop.x == 0) hand.col(0).copyTo(on_picture_border.col(0));
  if (crop.x + crop.width == picture.width) hand.col(ww - 1).copyTo(on_picture_border.col(ww - 1));
  const double diameter = RegionDiameter(hand);
  std::vector<BorderRun> runs =
      BorderRuns(on_picture_border, std::max(2, static_cast<int>(0.1 * diameter)));
  std::sort(runs.begin(), runs.end(), [](const BorderRun& a, const BorderRun& b) {
    return a.length < b.length;
  });
  const bool arm_at_border = !options.cut_forearm || wrist.arm;
  double cut_px = 0;
  if (arm_at_border && !runs.empty()) {
    // The arm's run. Longer than an arm is wide, it carries hand along the border with it: a
    // hand cut by a side next to the one the arm leaves by makes one run round the corner.
    if (wrist.arm) cut_px += std::max(0.0, runs.back().length - kArmRunRadii * wrist.palm_radius);
    runs.pop_back();
  }
  for (const BorderRun& r : runs) cut_px += r.length;
  if (diameter > 0 && cut_px > options.max_cut_share * diameter) {
    return Status(StatusCode::kNoHand,
                  what + ": the hand is cut by the picture's border (" +
                      std::to_string(static_cast<int>(std::lround(cut_px / work.scale))) +
                      " px of it lie on the border" + (arm_at_border ? " away from the arm" : "") +
                      "); the search needs the whole hand: use a picture with a margin around it");
  }
  return Status::Ok();
}

// Step 4: the arm cut off (4a) and the hand checked whole (4b). When the region's own runs along
// the border hold no arm and the hand would be refused as cut by the border, the arm is looked
// for once more through a strip along the border (kArmReachRadii): a band across the forearm
// where it leaves the picture breaks its run into pieces. Only a hand refused by the first look
// can change, and the second look's answer is kept only when it is not refused either.
Result<WristCut> CutArmOfWholeHand(const std::string& what,
                                   WorkingHand* work,
                                   cv::Size picture,
                                   const ImageEdgeOptions& options) {
  const WristCut wrist = CutArm(options, 0, &work->hand);
  const Status whole = CheckNotCutByBorder(what, *work, picture, wrist, options);
  if (whole.ok()) return wrist;
  // Only a refusal for want of an arm is looked at again; finding none, the first look cut
  // nothing, so the second starts from the same region.
  if (!options.cut_forearm || wrist.arm) return whole;
  WorkingHand banded = *work;
  banded.hand = work->hand.clone();
  const WristCut seen = CutArm(options, kArmReachRadii, &banded.hand);
  if (!seen.arm || !CheckNotCutByBorder(what, banded, picture, seen, options).ok()) return whole;
  *work = std::move(banded);
  return seen;
}

// Step 5: the silhouette contour with the converter's rule (a one-link label image).
EdgeResult Silhouette(const cv::Mat& hand) {
  LabelImage li;
  li.width = hand.cols;
  li.height = hand.rows;
  li.labels.assign(static_cast<size_t>(li.width) * li.height, 0);
  for (int y = 0; y < li.height; ++y) {
    const uint8_t* row = hand.ptr<uint8_t>(y);
    for (int x = 0; x < li.width; ++x) {
      li.labels[static_cast<size_t>(y) * li.width + x] = row[x] ? 1 : 0;
    }
  }
  return ExtractEdges(li, DefaultJointPairs(), EdgeOptions{});
}

// Step 6: Canny edges inside the hand (blur and thresholds for the working size), those near
// the contour dropped and the contour itself added: one outline.
cv::Mat HandEdges(const WorkingHand& work,
                  const EdgeResult& silhouette,
                  const ImageEdgeOptions& options) {
  const double s = work.s;
  cv::Mat grey, edges;
  cv::cvtColor(work.bgr, grey, cv::COLOR_BGR2GRAY);
  if (s == 1.0) {
    cv::GaussianBlur(grey, grey, {5, 5}, 0);
  } else {
    // OpenCV's sigma for a 5x5 kernel is 1.1 px; the gradient scales with 1/s.
    cv::GaussianBlur(grey, grey, {0, 0}, 1.1 * s);
  }
  cv::Canny(grey, edges, options.canny_low / s, options.canny_high / s, 3, true);
  if (options.interior_edges_only) {
    edges &= work.hand;
  } else {
    cv::Mat near_hand;
    cv::dilate(work.hand, near_hand, Ellipse(2 * options.dilate_px * s + 1));
    edges &= near_hand;
  }
  if (const int c = static_cast<int>(std::lround(options.contour_clearance_px * s)); c > 0) {
    cv::Mat near_contour = cv::Mat::zeros(edges.rows, edges.cols, CV_8U);
    for (const EdgePixel& p : silhouette.silhouette) near_contour.at<uint8_t>(p.row, p.col) = 255;
    cv::dilate(near_contour, near_contour, Ellipse(2 * c + 1));
    edges.setTo(0, near_contour);
  }
  for (const EdgePixel& p : silhouette.silhouette) edges.at<uint8_t>(p.row, p.col) = 255;
  return edges;
}

// Step 7: the query, normalised in working px, then every pixel quantity back in the
// picture's px (working x, continuous = (picture x - crop.x) * fx).
Status NormaliseToPicture(const std::string& what,
                          const WorkingHand& work,
                          cv::Size picture,
                          const EdgeResult& silhouette,
                          const cv::Mat& edges,
                          const WristCut& wrist,
                          QueryEdges* out) {
  const cv::Rect& crop = work.crop;
  const double fx = work.fx, fy = work.fy;
  const int w = picture.width, h = picture.height;
  out->kind = QueryInputKind::kPhoto;
  out->width = w;
  out->height = h;
  out->hand_pixels = static_cast<int64_t>(std::llround(silhouette.num_hand_pixels / (fx * fy)));
  out->touches_border =
      silhouette.touches_border &&
      (crop.x == 0 || crop.y == 0 || crop.x + crop.width == w || crop.y + crop.height == h);
  HANDDB_RETURN_IF_ERROR(Finish(what, NonZeroPixels(edges), silhouette.silhouette, out));
  out->work_scale = std::sqrt(fx * fy);
  out->centre_x = crop.x + out->centre_x / fx;
  out->centre_y = crop.y + out->centre_y / fy;
  out->diameter_px /= out->work_scale;
  out->scale *= out->work_scale;
  const auto to_source = [&](std::vector<EdgePixelXY>* pixels) {
    for (EdgePixelXY& p : *pixels) {
      p.x = std::clamp(static_cast<int>(crop.x + (p.x + 0.5) / fx), 0, w - 1);
      p.y = std::clamp(static_cast<int>(crop.y + (p.y + 0.5) / fy), 0, h - 1);
    }
    std::sort(pixels->begin(), pixels->end(), [](const EdgePixelXY& a, const EdgePixelXY& b) {
      return a.y != b.y ? a.y < b.y : a.x < b.x;
    });
    pixels->erase(std::unique(pixels->begin(),
                              pixels->end(),
                              [](const EdgePixelXY& a, const EdgePixelXY& b) {
                                return a.x == b.x && a.y == b.y;
                              }),
                  pixels->end());
  };
  to_source(&out->edge_pixels);
  to_source(&out->contour_pixels);
  if (wrist.palm_radius > 0) {
    out->palm_centre_x = crop.x + wrist.palm_centre.x / fx;
    out->palm_centre_y = crop.y + wrist.palm_centre.y / fy;
    out->palm_radius_px = wrist.palm_radius / out->work_scale;
  }
  out->forearm_cut = wrist.cut;
  if (wrist.arm && (wrist.dir.x != 0 || wrist.dir.y != 0)) {
    // Back to source px: the working image may be scaled differently in x and y.
    const double dx = wrist.dir.x / fx, dy = wrist.dir.y / fy;
    const double n = std::hypot(dx, dy);
    out->arm_found = true;
    out->arm_dir_x = dx / n;
    out->arm_dir_y = dy / n;
  }
  if (wrist.cut) {
    out->wrist_line = {crop.x + wrist.a.x / fx,
                       crop.y + wrist.a.y / fy,
                       crop.x + wrist.b.x / fx,
                       crop.y + wrist.b.y / fy};
  }
  return Status::Ok();
}

// The photo path, step by step (image_edges.h). `bgr` is ToBgr8 of the decoded picture;
// `source` is the picture's size in its file: larger than `bgr` when a huge JPEG was decoded
// reduced.
Result<QueryEdges> FromPhoto(const std::filesystem::path& path,
                             const cv::Mat& bgr,
                             cv::Size source,
                             const ImageEdgeOptions& options) {
  const std::string what = path.string();
  // The clean-up, the crop and Canny need some room: a picture a few px high or wide is a strip,
  // not a photo of a hand.
  if (source.width < kMinPhotoSide || source.height < kMinPhotoSide) {
    return Status(StatusCode::kInvalidArgument,
                  what + ": a " + std::to_string(source.width) + "x" +
                      std::to_string(source.height) + " picture is too thin to hold a hand (" +
                      std::to_string(kMinPhotoSide) + " px each way at least)");
  }
  const bool use_mask = !options.mask.empty();
  auto cand = HandCandidates(what, bgr, source, options);
  if (!cand.ok()) return cand.status();
  auto keep = RoiMask(what, options.roi, bgr.cols, bgr.rows);
  if (!keep.ok()) return keep.status();
  auto found = FindHand(what, *cand, *keep, use_mask, options);
  if (!found.ok()) return found.status();
  auto work = CropToWorkingSize(what, bgr, *cand, *keep, use_mask, *found, options);
  if (!work.ok()) return work.status();
  auto cut = CutArmOfWholeHand(what, &*work, bgr.size(), options);
  if (!cut.ok()) return cut.status();
  const WristCut wrist = *cut;
  const EdgeResult silhouette = Silhouette(work->hand);
  const cv::Mat edges = HandEdges(*work, silhouette, options);
  QueryEdges out;
  HANDDB_RETURN_IF_ERROR(
      NormaliseToPicture(what, *work, bgr.size(), silhouette, edges, wrist, &out));
  return out;
}

// A picture decoded reduced (a huge JPEG): every pixel quantity back in the file's pixels.
void ScaleToSource(cv::Size source, cv::Size decoded, QueryEdges* q) {
  const double fx = double(source.width) / decoded.width;
  const double fy = double(source.height) / decoded.height;
  const double f = std::sqrt(fx * fy);
  q->width = source.width;
  q->height = source.height;
  for (auto* pixels : {&q->edge_pixels, &q->contour_pixels}) {
    for (EdgePixelXY& p : *pixels) {
      p.x = std::min(source.width - 1, static_cast<int>((p.x + 0.5) * fx));
      p.y = std::min(source.height - 1, static_cast<int>((p.y + 0.5) * fy));
    }
  }
  q->hand_pixels = static_cast<int64_t>(std::llround(q->hand_pixels * fx * fy));
  q->work_scale /= f;
  q->palm_centre_x *= fx;
  q->palm_centre_y *= fy;
  q->palm_radius_px *= f;
  for (size_t i = 0; i < 4; ++i) q->wrist_line[i] *= i % 2 == 0 ? fx : fy;
  if (q->arm_found) {
    const double dx = q->arm_dir_x * fx, dy = q->arm_dir_y * fy, n = std::hypot(dx, dy);
    q->arm_dir_x = dx / n;
    q->arm_dir_y = dy / n;
  }
  q->centre_x *= fx;
  q->centre_y *= fy;
  q->diameter_px *= f;
  q->scale /= f;
}

// A crop in a picture of size `from`'s px -> the same crop in the picture resized to `to`.
void ScaleCrop(cv::Size from, cv::Size to, LandmarkCrop* crop) {
  const double fx = double(to.width) / from.width, fy = double(to.height) / from.height;
  crop->centre = {static_cast<float>(crop->centre.x * fx), static_cast<float>(crop->centre.y * fy)};
  crop->side *= static_cast<float>(std::sqrt(fx * fy));
}

// The same for the landmarks found in the reduced picture.
void ScaleToSource(cv::Size source, cv::Size decoded, HandLandmarks* l) {
  const double fx = double(source.width) / decoded.width;
  const double fy = double(source.height) / decoded.height;
  const double f = std::sqrt(fx * fy);
  for (Point2f& p : l->image_px) p = {static_cast<float>(p.x * fx), static_cast<float>(p.y * fy)};
  ScaleCrop(decoded, source, &l->crop);
  for (float& z : l->depth_px) z *= static_cast<float>(f);
}

Result<PictureEvidence> FromDecoded(const std::filesystem::path& image,
                                    const cv::Mat& any,
                                    cv::Size source,
                                    QueryInputKind kind,
                                    const ImageEdgeOptions& options,
                                    const LandmarkStep& landmarks);

// The picture decoded once: its edges, then (a photo, with a landmarker) the landmark network
// on the same pixels and the hand the segmentation found, both in the decoded picture's pixels
// until the last step maps them to the file's.
Result<PictureEvidence> Read(const std::filesystem::path& image,
                             const ImageEdgeOptions& options,
                             const LandmarkStep& landmarks) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "invalid image edge options (see the line above)");
  }
  // A JPEG above kMaxImagePixels is decoded at 1/2, 1/4 or 1/8 of its size (libjpeg scales
  // while it decodes, so the full image is never in memory).
  if (Status s = CheckImageFileComplete(image, kMaxImagePixels, kMaxJpegPixels); !s.ok()) return s;
  QueryInputKind kind = options.kind;
  if (kind == QueryInputKind::kAuto && Lower(image.extension().string()) == ".exr") {
    kind = QueryInputKind::kLabels;
  }
  PictureEvidence out;
  if (kind == QueryInputKind::kLabels) {
    auto edges = FromLabels(image, options);
    if (!edges.ok()) return edges.status();
    out.edges = std::move(edges).value();
    return out;
  }

  int flags = cv::IMREAD_UNCHANGED;
  const std::optional<ImageSize> size = ReadImageSize(image);
  if (size && std::string_view(size->format) == "JPEG" &&
      size->width * size->height > kMaxImagePixels) {
    const uint64_t pixels = size->width * size->height;
    flags = pixels <= 4 * kMaxImagePixels    ? cv::IMREAD_REDUCED_COLOR_2
            : pixels <= 16 * kMaxImagePixels ? cv::IMREAD_REDUCED_COLOR_4
                                             : cv::IMREAD_REDUCED_COLOR_8;
  }
  Result<cv::Mat> read = ReadImage(image, flags);
  if (!read.ok()) return read.status();
  const cv::Mat any = std::move(*read);
  if (any.empty()) {
    return Status(StatusCode::kBadImage,
                  image.string() + ": cannot read the image (not a PNG/JPEG/... or corrupt)");
  }
  const cv::Size source =
      flags == cv::IMREAD_UNCHANGED || !size
          ? any.size()
          : cv::Size(static_cast<int>(size->width), static_cast<int>(size->height));
  return FromDecoded(image, any, source, kind, options, landmarks);
}

// A decoded picture (`source`: its size in its file) -> its evidence: the edges of an edge image
// or a photo and, for a photo, the landmarks.
Result<PictureEvidence> FromDecoded(const std::filesystem::path& image,
                                    const cv::Mat& any,
                                    cv::Size source,
                                    QueryInputKind kind,
                                    const ImageEdgeOptions& options,
                                    const LandmarkStep& landmarks) {
  PictureEvidence out;
  if (kind == QueryInputKind::kAuto) {
    kind = LooksLikeEdgeImage(any) ? QueryInputKind::kEdges : QueryInputKind::kPhoto;
  }
  if (kind == QueryInputKind::kEdges) {
    auto edges = FromEdgeImage(image, any);
    if (!edges.ok()) return edges.status();
    out.edges = std::move(edges).value();
  } else {
    const cv::Mat bgr = ToBgr8(any);
    auto edges = FromPhoto(image, bgr, source, options);
    if (!edges.ok()) return edges.status();
    out.edges = std::move(edges).value();
    if (landmarks.landmarker != nullptr) {
      LandmarkStep step = landmarks;
      // The start crop is in the file's px; the network runs in the decoded picture's.
      if (step.start && source != any.size()) ScaleCrop(source, any.size(), &*step.start);
      out.landmarks = FindLandmarks(step, bgr, out.edges);
    }
  }
  if (source != any.size()) {
    ScaleToSource(source, any.size(), &out.edges);
    if (out.landmarks) ScaleToSource(source, any.size(), &*out.landmarks);
  }
  return out;
}

}  // namespace

std::string_view QueryInputKindName(QueryInputKind kind) {
  switch (kind) {
    case QueryInputKind::kPhoto:
      return "photo";
    case QueryInputKind::kEdges:
      return "edges";
    case QueryInputKind::kLabels:
      return "labels";
    case QueryInputKind::kAuto:
      break;
  }
  return "auto";
}

Result<QueryInputKind> ParseQueryInputKind(std::string_view name) {
  for (QueryInputKind k : {QueryInputKind::kAuto,
                           QueryInputKind::kPhoto,
                           QueryInputKind::kEdges,
                           QueryInputKind::kLabels}) {
    if (name == QueryInputKindName(k)) return k;
  }
  return Status(
      StatusCode::kInvalidArgument,
      "unknown input kind '" + std::string(name) + "' (expected auto, photo, edges or labels)");
}

bool SkinModel::Check() const {
  CHECK_OPTION(0 <= y_min && y_min <= y_max && y_max <= 255);
  CHECK_OPTION(0 <= cr_min && cr_min <= cr_max && cr_max <= 255);
  CHECK_OPTION(0 <= cb_min && cb_min <= cb_max && cb_max <= 255);
  return true;
}

bool PictureOptions::Check() const {
  CHECK_OPTION(edges.Check());
  CHECK_OPTION(landmark_passes == 1 || landmark_passes == 2);
  return true;
}

bool ImageEdgeOptions::Check() const {
  CHECK_OPTION(skin.Check());
  CHECK_OPTION(canny_low >= 0 && canny_low <= canny_high);
  CHECK_OPTION_GE(dilate_px, 0);
  CHECK_OPTION_LE(dilate_px, 100);
  CHECK_OPTION_GE(contour_clearance_px, 0);
  CHECK_OPTION_LE(contour_clearance_px, 20);
  CHECK_OPTION_GE(min_hand_pixels, 1);
  CHECK_OPTION(work_diameter_px == 0 || (work_diameter_px >= 16 && work_diameter_px <= 4096));
  CHECK_OPTION(wrist_cut_radii >= 1 && wrist_cut_radii <= 20);
  CHECK_OPTION(second_region_share >= 0 && second_region_share <= 1);
  CHECK_OPTION_GE(max_cut_share, 0);
  CHECK_OPTION(roi.empty() || (roi.width > 0 && roi.height > 0));
  CHECK_OPTION(label_edges.Check());
  return true;
}

Result<PixelRect> ParsePixelRect(std::string_view text) {
  int v[4];
  const char* p = text.data();
  const char* end = text.data() + text.size();
  for (int i = 0; i < 4; ++i) {
    const auto r = std::from_chars(p, end, v[i]);
    if (r.ec != std::errc() || (i < 3 && (r.ptr == end || *r.ptr != ',')) ||
        (i == 3 && r.ptr != end)) {
      return Status(StatusCode::kInvalidArgument,
                    "bad rectangle '" + std::string(text) + "' (expected x,y,w,h in pixels)");
    }
    p = r.ptr + 1;
  }
  if (v[0] < 0 || v[1] < 0 || v[2] <= 0 || v[3] <= 0) {
    return Status(StatusCode::kInvalidArgument,
                  "bad rectangle '" + std::string(text) + "' (x, y >= 0 and w, h > 0)");
  }
  return PixelRect{v[0], v[1], v[2], v[3]};
}

std::vector<Point2f> QueryEdges::points_px() const {
  std::vector<Point2f> out;
  out.reserve(points.size());
  for (const PointQ& p : points) out.push_back({PointQToPx(p.x), PointQToPx(p.y)});
  return out;
}

Result<QueryEdges> LoadQueryEdges(const std::filesystem::path& image,
                                  const ImageEdgeOptions& options) {
  auto read = Read(image, options, LandmarkStep{});
  if (!read.ok()) return read.status();
  return std::move(read->edges);
}

Result<PictureEvidence> ReadPicture(const std::filesystem::path& image,
                                    const PictureOptions& options) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "invalid picture options (see the line above)");
  }
  return Read(image, options.edges, StepOf(options));
}

Result<PictureEvidence> ReadPicturePixels(const std::string& name,
                                          const PicturePixels& pixels,
                                          const PictureOptions& options) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "invalid picture options (see the line above)");
  }
  if (options.edges.kind == QueryInputKind::kLabels) {
    return Status(StatusCode::kInvalidArgument,
                  name + ": a label picture is read from its EXR file, not from pixels");
  }
  const size_t row_bytes = pixels.row_bytes != 0
                               ? pixels.row_bytes
                               : static_cast<size_t>(pixels.width) * pixels.channels;
  if (pixels.data == nullptr || pixels.width <= 0 || pixels.height <= 0 ||
      (pixels.channels != 1 && pixels.channels != 3 && pixels.channels != 4) ||
      row_bytes < static_cast<size_t>(pixels.width) * pixels.channels ||
      static_cast<uint64_t>(pixels.width) * pixels.height > kMaxImagePixels) {
    return Status(StatusCode::kBadImage,
                  name + ": not a picture: " + std::to_string(pixels.width) + "x" +
                      std::to_string(pixels.height) + " px of " + std::to_string(pixels.channels) +
                      " channels");
  }
  // A header over the caller's bytes: every step reads them, none writes.
  const cv::Mat any(pixels.height,
                    pixels.width,
                    CV_MAKETYPE(CV_8U, pixels.channels),
                    const_cast<uint8_t*>(pixels.data),
                    row_bytes);
  return FromDecoded(name, any, any.size(), options.edges.kind, options.edges, StepOf(options));
}

}  // namespace handdb
