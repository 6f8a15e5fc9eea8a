// The second stage of a photo query: the exact chamfer search's nearest views,
// re-ranked by how well each view's 21 keypoints fit the hand landmarks a pretrained network
// found in the photo (photo/hand_landmarks.h). D_c alone confuses basic shapes whose
// outlines and inner edges agree (asl-0 with pinch and half-open, asl-5 with flat, asl-9 with B:
// docs/results.md); the landmarks say where the fingertips and knuckles are. Measured on the
// development photos and the rendered test sets (docs/decisions/0004-landmark-reranking.md).
//
// Score of a view v: D_c(v) / D_best + weight * E(v), where D_best is the smallest D_c of the
// pool and E(v) the mean distance between v's keypoints (rolled, mirrored for a left-hand match,
// in the query's normalised frame) and the landmarks mapped into that frame, divided by 96 px
// (half the normalised hand diameter of 192 px). The landmarks are used only when the
// network's presence score is at least min_presence; below it (no hand it recognises, or a view
// it was not trained on) the search keeps the D_c order.
#pragma once

#include <vector>

#include "base/status.h"
#include "photo/image_edges.h"
#include "query/searcher.h"

namespace handdb {

struct LandmarkRankOptions {
  bool enabled = true;
  double weight = 1.0;
  float min_presence = 0.9f;
  // The pool re-ranked: the nearest max(top_k, pool_views) views by D_c; when the search keeps
  // at most max_per_shape views of a shape (1: shapes ranked), the pool keeps
  // max(max_per_shape, pool_per_shape), so every shape near the photo brings a few views and
  // directions to fit the landmarks with. A search without a per-shape limit re-ranks its own
  // top max(top_k, pool_views) as they are. On the development photos, pools of 40 x 4 and
  // 208 x 8 rank alike (165 and 166 of 200 top-1) and 2 per shape loses 4-5 photos; the pool
  // search costs 1.27x the top-10 one (docs/decisions/0004-landmark-reranking.md).
  int pool_views = 40;
  int pool_per_shape = 4;
  // A search of either hand (SearchOptions::hand kEither) of a picture whose landmarks the
  // re-ranking uses searches one hand when the network names it: a handedness score above
  // `handedness` a right hand (the database's), below 1 - `handedness` a left one; else both.
  // 1: both hands always. The score is as the network gives it: for the picture as it is, above
  // 0.5 for a right hand (docs/decisions/0029).
  float handedness = 0.9f;
  bool Check() const;
};

// The hand SearchEvidence searches `picture` as, for a search of `asked` (see handedness above).
Hand SearchedHand(const PictureEvidence& picture, Hand asked, const LandmarkRankOptions& options);

// E(v) of a match for the picture's landmarks (see above). THROW_CHECK: the picture has
// landmarks.
double LandmarkError(const PictureEvidence& picture, const Match& match);

// True when the picture has landmarks the re-ranking uses (presence >= min_presence).
bool UsesLandmarks(const PictureEvidence& picture, const LandmarkRankOptions& options);

// Re-ranks `pool` (the pool search's matches, best D_c first) by the score above, then keeps
// the first top_k, at most max_per_shape of one shape (0: no limit). Sets landmark_error and
// score of each match kept.
std::vector<Match> RerankByLandmarks(std::vector<Match> pool,
                                     const PictureEvidence& picture,
                                     const SearchOptions& search,
                                     const LandmarkRankOptions& options);

// The search a picture's evidence gets: Searcher::Search on its points, and, when it has
// landmarks the re-ranking uses, the pool search and RerankByLandmarks. Errors as Search's.
Result<std::vector<Match>> SearchEvidence(const Searcher& searcher,
                                          const PictureEvidence& picture,
                                          const SearchOptions& search,
                                          const LandmarkRankOptions& options,
                                          SearchStats* stats = nullptr);

}  // namespace handdb
