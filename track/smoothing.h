// Smooth answers over time. A frame's search ranks its candidates alone; consecutive frames of a
// video show nearly the same pose, so among each frame's top k the sequence of choices that
// changes the pose least, for a small price in each frame's own ranking, is the steadier answer
// (per-frame answers otherwise flip between near-identical shapes and rolls).
//
// Cost of a choice c_t per frame t: sum_t unary(c_t) + sum_t transition(c_{t-1}, c_t), minimised
// exactly by dynamic programming (Viterbi) over the frames' candidates: offline over the whole
// sequence, online over a short look-back window that ends at the newest frame. A frame without
// candidates (no hand) breaks the chain.
//
// Then the chosen pose's keypoints, in the frame's px and in 3D (the fit's, in the picture's
// normalised frame), are filtered (a One Euro filter: a low-pass whose cut-off rises with the
// speed, so a still hand stops shaking and a moving one does not lag): forward only online,
// forward and backward averaged offline.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <vector>

#include "base/status.h"
#include "format/view.h"
#include "query/searcher.h"

namespace handdb {

struct TransitionCosts {
  // Per radian: the RMS change of the 20 joint angles, the angle between view directions, the
  // change of the hand's in-picture axis (wrist -> middle knuckle, wrapped to [0, pi]).
  double joint = 1.0;
  double view = 0.5;
  double roll = 0.5;
  double hand = 1.0;  // a change of hand
  bool Check() const;
};

// What the smoother knows of one candidate.
struct PoseCandidate {
  double unary = 0;  // the frame's own cost of it: 0 for the frame's best
  std::array<float, kNumJointAngles> joints{};
  std::array<float, 3> view_direction{};
  double axis_angle = 0;  // in-picture angle of wrist -> middle knuckle, radians
  Hand hand = Hand::kRight;
};

// A frame's matches as candidates: unary = score - best score when landmarks re-ranked them
// (Match::score >= 0), else D_c / best D_c - 1.
std::vector<PoseCandidate> CandidatesOf(const std::vector<Match>& matches);

double TransitionCost(const PoseCandidate& from,
                      const PoseCandidate& to,
                      const TransitionCosts& costs);

// One choice per frame (an index into its candidates; -1 for a frame without any) minimising
// the cost above, segment by segment between frames without candidates. Ties go to the lower
// index.
std::vector<int> ChooseByDynamicProgramming(const std::vector<std::vector<PoseCandidate>>& frames,
                                            const TransitionCosts& costs);

struct KeypointFilterOptions {
  bool enabled = true;
  double min_cutoff_hz = 1.5;  // the cut-off of a still hand
  double beta = 0.1;           // how fast the cut-off rises with speed (per px/s)
  double d_cutoff_hz = 1.0;    // the cut-off of the speed's own estimate
  bool Check() const;
};

using Keypoints2d = std::array<Point2f, kNumKeypoints>;
// Normalised px with depth, as a view label's keypoints (format/view.h).
using Keypoints3d = std::array<std::array<float, 3>, kNumKeypoints>;

// A One Euro filter of 21 keypoints, each coordinate on its own (its speed, its cut-off); K is
// Keypoints2d or Keypoints3d. The options' units are px: the frame's, or the normalised frame's
// (a hand ~192 px across).
template <typename K>
class KeypointFilter {
 public:
  explicit KeypointFilter(const KeypointFilterOptions& options) : options_(options) {}
  // The filtered keypoints at time t (seconds, increasing; a time not after the last one's
  // returns the last output).
  K Filter(const K& raw, double t);
  void Reset() { last_t_.reset(); }

 private:
  static constexpr size_t kValues = sizeof(K) / sizeof(float);
  KeypointFilterOptions options_;
  std::optional<double> last_t_;
  std::array<double, kValues> x_{};
  std::array<double, kValues> dx_{};
};

// Offline: each run of consecutive frames with keypoints (nullopt ends a run) filtered forward
// and backward, the two averaged (no lag either way).
template <typename K>
std::vector<std::optional<K>> FilterSequence(const std::vector<std::optional<K>>& keypoints,
                                             const std::vector<double>& times,
                                             const KeypointFilterOptions& options);

extern template class KeypointFilter<Keypoints2d>;
extern template class KeypointFilter<Keypoints3d>;

}  // namespace handdb
