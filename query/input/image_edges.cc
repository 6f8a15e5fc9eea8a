#include "query/input/image_edges.h"

#include <algorithm>
#include <charconv>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <system_error>
#include <utility>

#include "base/image_file.h"
#include "edges/edges.h"
#include "edges/exr_io.h"
#include "edges/normalise.h"
#include "edges/view_conversion.h"

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

Result<QueryEdges> FromPhoto(const std::filesystem::path& path,
                             const cv::Mat& any,
                             const ImageEdgeOptions& options) {
  const std::string what = path.string();
  cv::Mat bgr;
  if (any.depth() != CV_8U) {
    any.convertTo(bgr, CV_8U, any.depth() == CV_16U ? 1.0 / 257.0 : 255.0);
  } else {
    bgr = any;
  }
  if (bgr.channels() == 1) cv::cvtColor(bgr, bgr, cv::COLOR_GRAY2BGR);
  if (bgr.channels() == 4) cv::cvtColor(bgr, bgr, cv::COLOR_BGRA2BGR);
  const int w = bgr.cols;
  const int h = bgr.rows;

  // 1. Hand candidates: the mask, or skin colour.
  cv::Mat cand;
  if (!options.mask.empty()) {
    std::error_code ec;
    if (!std::filesystem::exists(options.mask, ec)) {
      return Status(StatusCode::kNotFound, options.mask.string() + ": no such mask file");
    }
    const cv::Mat m = cv::imread(options.mask.string(), cv::IMREAD_GRAYSCALE);
    if (m.empty()) {
      return Status(StatusCode::kBadImage, options.mask.string() + ": cannot read the mask image");
    }
    if (m.cols != w || m.rows != h) {
      return Status(StatusCode::kBadImage,
                    options.mask.string() + ": mask is " + std::to_string(m.cols) + "x" +
                        std::to_string(m.rows) + ", the image " + std::to_string(w) + "x" +
                        std::to_string(h));
    }
    cand = m != 0;
  } else {
    cv::Mat ycrcb;
    cv::cvtColor(bgr, ycrcb, cv::COLOR_BGR2YCrCb);
    const SkinModel& s = options.skin;
    cv::inRange(ycrcb,
                cv::Scalar(s.y_min, s.cr_min, s.cb_min),
                cv::Scalar(s.y_max, s.cr_max, s.cb_max),
                cand);
    // Remove speckle, close small gaps.
    const cv::Mat k3 = cv::getStructuringElement(cv::MORPH_ELLIPSE, {3, 3});
    const cv::Mat k5 = cv::getStructuringElement(cv::MORPH_ELLIPSE, {5, 5});
    cv::morphologyEx(cand, cand, cv::MORPH_OPEN, k3);
    cv::morphologyEx(cand, cand, cv::MORPH_CLOSE, k5);
  }
  if (!options.roi.empty()) {
    const PixelRect& r = options.roi;
    if (r.x < 0 || r.y < 0 || r.x + r.width > w || r.y + r.height > h) {
      return Status(StatusCode::kInvalidArgument,
                    what + ": ROI " + std::to_string(r.x) + "," + std::to_string(r.y) + "," +
                        std::to_string(r.width) + "," + std::to_string(r.height) +
                        " is not inside the " + std::to_string(w) + "x" + std::to_string(h) +
                        " image");
    }
    cv::Mat keep = cv::Mat::zeros(h, w, CV_8U);
    keep(cv::Rect(r.x, r.y, r.width, r.height)).setTo(255);
    cand &= keep;
  }

  // 2. The largest 8-connected region is the hand.
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(cand, labels, stats, centroids, 8, CV_32S);
  int best = 0;
  int best_area = 0;
  for (int i = 1; i < n; ++i) {
    const int area = stats.at<int>(i, cv::CC_STAT_AREA);
    if (area > best_area) {
      best_area = area;
      best = i;
    }
  }
  if (best_area < options.min_hand_pixels) {
    return Status(StatusCode::kNoHand,
                  what + ": no hand found (largest " +
                      std::string(options.mask.empty() ? "skin-coloured" : "mask") +
                      " region has " + std::to_string(best_area) + " pixels, need " +
                      std::to_string(options.min_hand_pixels) + ")");
  }
  const cv::Mat hand = labels == best;

  // 3. Silhouette contour with the converter's rule (a one-link label image).
  LabelImage li;
  li.width = w;
  li.height = h;
  li.labels.assign(static_cast<size_t>(w) * h, 0);
  for (int y = 0; y < h; ++y) {
    const uint8_t* row = hand.ptr<uint8_t>(y);
    for (int x = 0; x < w; ++x) li.labels[static_cast<size_t>(y) * w + x] = row[x] ? 1 : 0;
  }
  const EdgeResult silhouette = ExtractEdges(li, DefaultJointPairs(), EdgeOptions{});

  // 4. Canny edges near the hand, plus the contour.
  cv::Mat grey, edges;
  cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  cv::GaussianBlur(grey, grey, {5, 5}, 0);
  cv::Canny(grey, edges, options.canny_low, options.canny_high, 3, true);
  cv::Mat near_hand;
  const int d = options.dilate_px;
  cv::dilate(hand, near_hand, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * d + 1, 2 * d + 1}));
  edges &= options.interior_edges_only ? hand : near_hand;
  if (const int c = options.contour_clearance_px; c > 0) {
    cv::Mat near_contour = cv::Mat::zeros(h, w, CV_8U);
    for (const EdgePixel& p : silhouette.silhouette) near_contour.at<uint8_t>(p.row, p.col) = 255;
    cv::dilate(near_contour,
               near_contour,
               cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * c + 1, 2 * c + 1}));
    edges.setTo(0, near_contour);
  }
  for (const EdgePixel& p : silhouette.silhouette) edges.at<uint8_t>(p.row, p.col) = 255;

  QueryEdges out;
  out.kind = QueryInputKind::kPhoto;
  out.width = w;
  out.height = h;
  out.hand_pixels = silhouette.num_hand_pixels;
  out.touches_border = silhouette.touches_border;
  HANDDB_RETURN_IF_ERROR(Finish(what, NonZeroPixels(edges), silhouette.silhouette, &out));
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

bool ImageEdgeOptions::Check() const {
  CHECK_OPTION(skin.Check());
  CHECK_OPTION(canny_low >= 0 && canny_low <= canny_high);
  CHECK_OPTION_GE(dilate_px, 0);
  CHECK_OPTION_LE(dilate_px, 100);
  CHECK_OPTION_GE(contour_clearance_px, 0);
  CHECK_OPTION_LE(contour_clearance_px, 20);
  CHECK_OPTION_GE(min_hand_pixels, 1);
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
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "invalid image edge options (see the line above)");
  }
  if (Status s = CheckImageFileComplete(image); !s.ok()) return s;  // issue 14 items 6, 7, 8
  QueryInputKind kind = options.kind;
  if (kind == QueryInputKind::kAuto && Lower(image.extension().string()) == ".exr") {
    kind = QueryInputKind::kLabels;
  }
  if (kind == QueryInputKind::kLabels) return FromLabels(image, options);

  const cv::Mat any = cv::imread(image.string(), cv::IMREAD_UNCHANGED);
  if (any.empty()) {
    return Status(StatusCode::kBadImage,
                  image.string() + ": cannot read the image (not a PNG/JPEG/... or corrupt)");
  }
  if (kind == QueryInputKind::kAuto) {
    kind = LooksLikeEdgeImage(any) ? QueryInputKind::kEdges : QueryInputKind::kPhoto;
  }
  if (kind == QueryInputKind::kEdges) return FromEdgeImage(image, any);
  return FromPhoto(image, any, options);
}

}  // namespace handdb
