// The fitted pose of a picture: the pose fit (pose/fit.h) run from each of a search's first
// matches, each in the query's own frame; the answer is the fit of least final cost. A match is a
// stored view on the database's grid of shapes, directions and rolls; its fit moves the 20 joint
// angles, the rotation and the scale and shift off that grid towards the picture's hand landmarks
// or, where there are none, its silhouette (docs/photo.md "Fitted pose").
//
// Why the final cost: it holds the prior, so a fit that had to leave its match far behind to meet
// the landmarks costs more than one that met them near its match. The landmark cost alone picked
// the worse 3D pose (the landmarks are 2D, and fits from different starts end at nearly the same
// landmark cost with different depths: docs/decisions/0015); the final cost among the first 3
// fits lowered the median 3D error below the first match's fit's (docs/decisions/0016).
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
  // Fit the first this many matches (a few ms each on one core) and answer with the one of least
  // final cost: on the natural-pose photo renders the median 3D error of the answer fell from
  // 0.233 (the first match's fit) to 0.222 hand sizes with 3, 0.213 with 5 and 0.212 with 10;
  // 3 keeps a photo's fits within ~15 ms (docs/decisions/0016).
  int max_matches = 3;
  // The landmarks are evidence when the network's presence score reaches this. Lower than the
  // re-ranking's 0.9 (pose/landmark_rank.h): on photo renders the network often scores real
  // hands 0.5-0.9, and fits to those landmarks still moved the top match's 3D error from 0.53 to
  // 0.39 (median; docs/decisions/0015).
  float min_presence = 0.5f;
  // The silhouette term (pose/fit_silhouette.h): a picture without usable landmarks (an edge
  // image, a label EXR, a photo whose presence is below min_presence) is fitted to its
  // silhouette alone, with `silhouette_fit`, from its first `max_silhouette_matches` matches.
  // Off unless asked for (`--fit on`): alone it does not yet improve on the match (label renders
  // 0.310 -> 0.325, photos without their landmarks 0.442 -> 0.472, median wrist-to-middle-knuckle
  // lengths), and beside the landmarks it did not lower the photo renders' 3D error (0.378 with
  // it, 0.374 without; docs/decisions/0016).
  bool use_silhouette = false;
  bool silhouette_with_landmarks = false;
  SilhouetteFieldOptions silhouette;
  // The silhouette is 2D and says little about depth: with the landmark fit's priors (0.5 rad a
  // joint, 0.35 rad the rotation) the label renders' fits lost 3D accuracy (0.255 against the
  // top match's 0.206 hand sizes); held to 0.2 and 0.1 rad, and without the edge part (which
  // pulls link sides onto the wrong creases), they stay near it (0.209; docs/decisions/0016).
  PoseFitOptions silhouette_fit = [] {
    PoseFitOptions o;
    o.function_tolerance = 1e-4;
    o.joint_prior_sigma = 0.2;
    o.rotation_prior_sigma = 0.1;
    o.edge_weight = 0;
    return o;
  }();
  // A silhouette fit costs ~20 ms: the first match only (choosing among three by cost was no
  // better on the label renders).
  int max_silhouette_matches = 1;
  FitChoice choice = FitChoice::kLeastCost;
  // The matches are fitted on up to this many threads (the same fits on any number): a single
  // picture's query fits its 3 matches beside each other; a batch, whose pictures already share
  // the threads, one after another.
  int num_threads = 1;
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
