// The fitted pose of a picture: the pose fit (pose/fit.h) run from each of a search's first
// matches, each in the query's own frame, and the best fit by its final cost chosen as the
// answer. A match is a stored view on the database's grid of shapes, directions and rolls; its
// fit moves the 20 joint angles, the rotation and the scale and shift off that grid towards the
// picture's hand landmarks (docs/photo.md "Fitted pose").
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

struct MatchFitOptions {
  PoseFitOptions fit;
  // Fit the first this many matches (each ~1-5 ms on one core). The best fit among them is the
  // answer, so a candidate that ranks 3rd but whose pose explains the picture better wins.
  int max_matches = 10;
  // The landmarks are evidence when the network's presence score reaches this (the re-ranking's
  // threshold, pose/landmark_rank.h): below it the joints are unreliable.
  float min_presence = 0.9f;
  bool Check() const;
};

// One match's fit, in the query's normalised frame (x right, y down, px; a hand is 192 px
// across) and the picture's px.
struct MatchFit {
  bool fitted = false;  // false: the match stands as it was; `reason` says why
  std::string reason;   // "no landmarks", "landmark presence 0.42 below 0.9", a fit error
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
  std::vector<MatchFit> fits;  // one per fitted match, in the matches' order
  int best = -1;               // index of the fit with the smallest final cost; -1: none fitted
};

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
