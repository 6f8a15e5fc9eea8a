// The fitted pose of a picture: the pose fit (pose/fit.h) run from each of a search's first
// matches, each in the query's own frame; the answer is the fit of the best-ranked match that
// could be fitted. A match is a stored view on the database's grid of shapes, directions and
// rolls; its fit moves the 20 joint angles, the rotation and the scale and shift off that grid
// towards the picture's hand landmarks (docs/photo.md "Fitted pose").
//
// Why the rank and not the smallest cost: the landmarks are 2D, so fits from different starts
// end at nearly the same landmark cost with different depths, and the smallest cost picked the
// worse 3D pose (natural-pose photo renders, paper database: median 0.42 against 0.37
// wrist-to-middle-knuckle lengths for the top match's fit; docs/decisions/0015).
//
// A left-hand match (Match::hand == kLeft) is fitted as the database's right hand to the
// mirrored picture, then mirrored back: its keypoints are where the left hand's joints are, its
// rotation and view direction are in the left hand's frame (the right hand's with y negated,
// as MirrorLabel defines it).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "base/status.h"
#include "generator/hand/database_rig.h"
#include "photo/image_edges.h"
#include "pose/fit.h"
#include "query/database.h"
#include "query/searcher.h"

namespace handdb {

// Which fit is the answer.
enum class FitChoice {
  kFirstFitted,  // the best-ranked match that could be fitted
  kLeastCost,    // the fit with the smallest final cost (landmarks, silhouette and prior)
};

struct MatchFitOptions {
  // The fit stops once a step lowers the cost by less than 1e-4 of it: on the natural-pose renders
  // half the iterations of Ceres' default 1e-6 for the same 3D error (docs/decisions/0015).
  PoseFitOptions fit = [] {
    PoseFitOptions o;
    o.function_tolerance = 1e-4;
    return o;
  }();
  // Fit the first this many matches (a few ms each on one core); the answer is the first fitted
  // one, the others are reported beside their matches.
  int max_matches = 1;
  // The landmarks are evidence when the network's presence score reaches this. Lower than the
  // re-ranking's 0.9 (pose/landmark_rank.h): on photo renders the network often scores real
  // hands 0.5-0.9, and fits to those landmarks still moved the top match's 3D error from 0.53 to
  // 0.39 (median; docs/decisions/0015).
  float min_presence = 0.5f;
  // The silhouette term (pose/fit_silhouette.h): every picture with a hand region has it, so a
  // picture without landmarks (an edge image, a label EXR, a photo whose presence is below
  // min_presence) is fitted to its silhouette and edges alone.
  bool use_silhouette = true;
  SilhouetteFieldOptions silhouette;
  FitChoice choice = FitChoice::kFirstFitted;
  bool Check() const;
};

// One match's fit, in the query's normalised frame (x right, y down, px; a hand is 192 px
// across) and the picture's px.
struct MatchFit {
  bool fitted = false;  // false: the match stands as it was; `reason` says why
  std::string reason;   // "no landmarks and no silhouette (...)", a fit error
  PoseFit fit;          // valid when fitted (mirrored back for a left-hand match)
  // Keypoints in the normalised frame with depth: x, y as fit.keypoints_normalised, z the depth
  // away from the camera relative to the rig's look-at point (the database labels' keypoints'
  // convention), normalised px.
  std::array<std::array<double, 3>, kNumKeypoints> keypoints_3d{};
  std::array<Point2f, kNumKeypoints> keypoints_image_px{};  // the picture's px
  // Mean distance (normalised px) of the 21 keypoints from the landmarks: the match's own
  // keypoints, and the fitted ones.
  double landmark_error_start_px = 0;
  double landmark_error_px = 0;
};

struct PictureFit {
  std::vector<MatchFit> fits;    // one per fitted match, in the matches' order
  int best = -1;                 // the answer (MatchFitOptions::choice); -1: none fitted
  bool landmarks_used = false;   // the fits used the landmarks
  bool silhouette_used = false;  // and the silhouette term
};

// A camera rotation between the right hand's frame and the left hand's (the right hand's with y
// negated) in the mirrored picture (the camera's x negated): S_x R S_y, its own inverse. A
// left-hand MatchFit's cam_from_hand is the right-hand fit's through it, and back again.
Mat3d MirrorCamFromHand(const Mat3d& cam_from_hand);

// The picture's hand region (what its silhouette's outline pixels enclose) and edge points as the
// fit's distance fields, in its normalised frame. Errors: MakeSilhouetteFields'.
Result<SilhouetteFields> PictureSilhouetteFields(const PictureEvidence& picture,
                                                 const SilhouetteFieldOptions& options);

// Fits the first options.max_matches of `matches` (a search of `picture` in `database`, whose
// rig is `rig`). Errors: kInvalidArgument for options; a match that cannot be fitted (no
// landmarks, a label the rig cannot pose, a solver failure) is reported in its MatchFit, never
// as an error.
Result<PictureFit> FitPictureMatches(const DatabaseRig& rig,
                                     const Database& database,
                                     const PictureEvidence& picture,
                                     const std::vector<Match>& matches,
                                     const MatchFitOptions& options);

}  // namespace handdb
