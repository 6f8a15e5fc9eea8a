#include "pose/fit_matches.h"

#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <utility>

#include "base/thread_pool.h"

namespace handdb {
namespace {

// The picture's landmarks in its normalised frame (the inverse of QueryEdges::ImageFromNormalised),
// x negated for a left-hand match, whose fit is of the right hand to the mirrored picture.
NormalisedKeypoints2d LandmarksNormalised(const PictureEvidence& picture, bool mirrored) {
  const QueryEdges& q = picture.edges;
  NormalisedKeypoints2d out{};
  for (int k = 0; k < kNumKeypoints; ++k) {
    const Point2f& p = picture.landmarks->image_px[k];
    const double x = (p.x - q.centre_x) * q.scale;
    const double y = (p.y - q.centre_y) * q.scale;
    out[k] = {static_cast<float>(mirrored ? -x : x), static_cast<float>(y)};
  }
  return out;
}

// The network's world joints' depths in their own wrist-to-middle-knuckle lengths (the fit's
// depth evidence, pose/fit.h). Mirroring the picture negates x only, so a left-hand match reads
// the same depths. A degenerate or non-finite world hand gives NaN depths, which the fit refuses.
std::array<float, kNumKeypoints> WorldDepths(const HandLandmarks& landmarks) {
  const auto& w = landmarks.world_m;
  const double length =
      std::hypot(double{w[9][0]} - w[0][0], double{w[9][1]} - w[0][1], double{w[9][2]} - w[0][2]);
  std::array<float, kNumKeypoints> out{};
  for (int k = 0; k < kNumKeypoints; ++k) {
    out[k] =
        length > 0 ? static_cast<float>(w[k][2] / length) : std::numeric_limits<float>::quiet_NaN();
  }
  return out;
}

double MeanDistance(const NormalisedKeypoints2d& a, const NormalisedKeypoints2d& b) {
  double sum = 0;
  for (int k = 0; k < kNumKeypoints; ++k) sum += std::hypot(a[k].x - b[k].x, a[k].y - b[k].y);
  return sum / kNumKeypoints;
}

// The depth of each fitted keypoint (normalised px, away from the camera, relative to the look-at
// point), as ProjectToRenderPx and the normalisation give the labels' keypoints their z.
std::array<double, kNumKeypoints> Depths(const HandRig& rig, const PoseFit& fit) {
  std::array<double, kNumKeypoints> z{};
  for (int k = 0; k < kNumKeypoints; ++k) {
    double d = 0;
    for (int c = 0; c < 3; ++c) {
      d += fit.cam_from_hand[2][c] * (fit.keypoints_in_hand[k][c] - rig.look_at()[c]);
    }
    z[k] = fit.scale * d;
  }
  return z;
}

// A right-hand fit to the mirrored picture as the left hand in the picture itself: the camera's
// x and the hand frame's y change sign (cam_from_hand -> S_x R S_y, a rotation again), and with
// them the keypoints' x, the view direction's y and the roll, as MirrorLabel does for labels.
void MirrorFit(PoseFit* fit) {
  fit->cam_from_hand = MirrorCamFromHand(fit->cam_from_hand);
  fit->view_direction[1] = -fit->view_direction[1];
  fit->roll = -fit->roll;
  fit->shift[0] = -fit->shift[0];
  for (auto& p : fit->keypoints_normalised) p.x = -p.x;
}

// The silhouette's outline pixels in the normalised frame (x negated for the mirrored picture is
// left to the fit, which reads the fields mirrored).
std::vector<Point2f> OutlineNormalised(const QueryEdges& q) {
  std::vector<Point2f> out;
  out.reserve(q.contour_pixels.size());
  for (const EdgePixelXY& p : q.contour_pixels) {
    out.push_back({static_cast<float>((p.x + 0.5 - q.centre_x) * q.scale),
                   static_cast<float>((p.y + 0.5 - q.centre_y) * q.scale)});
  }
  return out;
}

std::string PresenceReason(float presence, float min_presence) {
  std::ostringstream s;
  s.precision(3);
  s << "landmark presence " << presence << " below " << min_presence;
  return s.str();
}

}  // namespace

Mat3d MirrorCamFromHand(const Mat3d& cam_from_hand) {
  Mat3d out = cam_from_hand;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      if ((r == 0) != (c == 1)) out[r][c] = -out[r][c];
    }
  }
  return out;
}

Result<SilhouetteFields> PictureSilhouetteFields(const PictureEvidence& picture,
                                                 const SilhouetteFieldOptions& options) {
  return MakeSilhouetteFields(OutlineNormalised(picture.edges), picture.edges.points, options);
}

bool MatchFitOptions::Check() const {
  if (!fit.Check()) return false;
  CHECK_OPTION_GE(max_matches, 0);
  CHECK_OPTION(min_presence >= 0.0f && min_presence <= 1.0f);
  if (!silhouette.Check()) return false;
  if (!silhouette_fit.Check()) return false;
  CHECK_OPTION_GE(max_silhouette_matches, 0);
  CHECK_OPTION(num_threads >= 1 && num_threads <= 256);
  return true;
}

Result<PictureFit> FitPictureMatches(const DatabaseRig& rig,
                                     const Database& database,
                                     const PictureEvidence& picture,
                                     const std::vector<Match>& matches,
                                     const MatchFitOptions& options) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "pose fit: options fail their checks (see above)");
  }
  PictureFit out;
  const size_t n = std::min(matches.size(), static_cast<size_t>(options.max_matches));
  out.fits.resize(n);

  std::string no_landmarks;
  if (!picture.landmarks.has_value() || !(picture.edges.scale > 0)) {
    no_landmarks = "no landmarks";
  } else if (!(picture.landmarks->presence >= options.min_presence)) {
    no_landmarks = PresenceReason(picture.landmarks->presence, options.min_presence);
  }
  std::shared_ptr<const SilhouetteFields> fields;
  std::string no_silhouette;
  if (!options.use_silhouette) {
    no_silhouette = "the silhouette term is off";
  } else if (!(picture.edges.scale > 0)) {
    no_silhouette = "no normalisation";
  } else if (n > 0 && (options.silhouette_with_landmarks || !no_landmarks.empty())) {
    auto made = PictureSilhouetteFields(picture, options.silhouette);
    if (made.ok()) {
      fields = std::make_shared<const SilhouetteFields>(std::move(made).value());
    } else {
      no_silhouette = made.status().message();
    }
  }
  out.landmarks_used = no_landmarks.empty() && n > 0;
  if (out.landmarks_used && !options.silhouette_with_landmarks) fields.reset();
  out.silhouette_used = fields != nullptr;
  std::string no_evidence;
  if (!out.landmarks_used && !out.silhouette_used) {
    no_evidence = no_landmarks + " and no silhouette (" + no_silhouette + ")";
  }

  // Each match's fit is independent of the others': on several threads they are the same fits.
  auto fit_one = [&](size_t i, int) {
    const Match& match = matches[i];
    MatchFit& mf = out.fits[i];
    if (!no_evidence.empty()) {
      mf.reason = no_evidence;
      return true;
    }
    if (!out.landmarks_used && i >= static_cast<size_t>(options.max_silhouette_matches)) {
      mf.reason = "a silhouette fit is made of the first " +
                  std::to_string(options.max_silhouette_matches) + " matches only";
      return true;
    }
    const bool mirrored = match.hand == Hand::kLeft;
    // The stored view's own label (right hand, roll 0): the start of its virtual view (v, r).
    auto start =
        PoseFitStartFromLabel(rig.rig, database.label(match.view_id), rig.render, match.roll_angle);
    if (!start.ok()) {
      mf.reason = start.status().message();
      return true;
    }
    PoseFitEvidence evidence;
    if (out.landmarks_used) {
      evidence.has_landmarks = true;
      evidence.landmarks_px = LandmarksNormalised(picture, mirrored);
      evidence.weights.fill(picture.landmarks->presence);
      if (picture.landmarks->has_world && options.fit.depth_weight > 0) {
        evidence.has_depths = true;
        evidence.depths = WorldDepths(*picture.landmarks);
      }
    }
    evidence.silhouette = fields;
    evidence.silhouette_mirrored = mirrored;
    auto fit = FitPose(
        rig.rig, *start, evidence, out.landmarks_used ? options.fit : options.silhouette_fit);
    if (!fit.ok()) {
      mf.reason = fit.status().message();
      return true;
    }
    if (fit->termination == "FAILURE") {  // the answer is the start: the match stands
      mf.reason = "the solver failed: " + fit->message;
      return true;
    }
    if (out.landmarks_used) {
      mf.landmark_error_start_px = MeanDistance(start->keypoints_normalised, evidence.landmarks_px);
      mf.landmark_error_px = MeanDistance(fit->keypoints_normalised, evidence.landmarks_px);
    }
    const std::array<double, kNumKeypoints> depth = Depths(rig.rig, *fit);
    mf.fit = std::move(fit).value();
    if (mirrored) MirrorFit(&mf.fit);
    for (int k = 0; k < kNumKeypoints; ++k) {
      const Point2f& p = mf.fit.keypoints_normalised[k];
      mf.keypoints_3d[k] = {p.x, p.y, depth[k]};
      mf.keypoints_image_px[k] = picture.edges.ImageFromNormalised(p);
    }
    mf.fitted = true;
    return true;
  };
  ParallelFor(n, options.num_threads, fit_one);
  for (size_t i = 0; i < n; ++i) {
    if (!out.fits[i].fitted) continue;
    if (out.best < 0 || (options.choice == FitChoice::kLeastCost &&
                         out.fits[i].fit.final_cost < out.fits[out.best].fit.final_cost)) {
      out.best = static_cast<int>(i);
    }
  }
  return out;
}

}  // namespace handdb
