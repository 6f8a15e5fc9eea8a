// The neighbourhood of a pose among a database's views: where a hand seen in one frame of a video
// can be in the next. A tracker searches it first (SearchOptions::subset, exact within it, with
// the full search's bounds), because consecutive frames of a video move the hand a little: its
// view direction by a few degrees, its roll by a step or two, its shape towards a nearby one.
//
// Built once per database from the views' labels (their view directions, joint angles and the
// in-picture axis of their keypoints), then asked per frame.
#pragma once

#include <cstdint>
#include <vector>

#include "format/roll.h"
#include "format/view.h"
#include "query/database.h"
#include "query/searcher.h"

namespace handdb {

struct NeighbourhoodOptions {
  // Views whose direction (hand -> camera, in the hand's frame) is within this angle of the
  // previous view's.
  double direction_deg = 30;
  // Rolls within this many steps of the previous answer's in-picture orientation, each
  // neighbouring view's roll centred on the step that turns its hand axis (wrist -> middle
  // knuckle) onto the previous answer's; a database of R rolls steps 360 / R degrees.
  int roll_steps = 2;
  // Shapes: < 0 every shape of the neighbouring directions; >= 0 only views whose joint angles are
  // within this RMS distance (radians) of the previous view's (0: the same joint angles).
  double joint_radius = -1;
  bool Check() const;
};

// The in-picture angle (radians, atan2 of y down over x) of a label's hand axis, wrist -> middle
// knuckle: what the neighbourhood's rolls and the smoother's roll cost compare.
float HandAxisAngle(const ViewLabel& label);

class ViewNeighbourhood {
 public:
  // Reads every view's label once.
  explicit ViewNeighbourhood(const Database& db);

  // The (view, roll, hand) pairs near `previous` (a match of the same database), all of
  // previous.hand, `previous`'s own pair among them. Sorted by (view, roll).
  std::vector<SearchPair> Near(const Match& previous, const NeighbourhoodOptions& options) const;

  size_t num_views() const { return views_.size(); }
  uint32_t num_rolls() const { return num_rolls_; }

 private:
  struct ViewInfo {
    std::array<float, 3> direction{};
    std::array<float, kNumJointAngles> joints{};
    float axis_angle = 0;  // of wrist -> middle knuckle in the canonical view, radians
  };
  std::vector<ViewInfo> views_;
  uint32_t num_rolls_ = 1;
};

}  // namespace handdb
