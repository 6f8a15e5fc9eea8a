#include "track/neighbourhood.h"

#include <algorithm>
#include <cmath>

#include "base/status.h"

namespace handdb {

float HandAxisAngle(const ViewLabel& label) {
  // Keypoints (docs/conventions.md): 0 wrist, 9 middle-finger MCP.
  const auto& w = label.keypoints[0];
  const auto& m = label.keypoints[9];
  return std::atan2(m[1] - w[1], m[0] - w[0]);
}

bool NeighbourhoodOptions::Check() const {
  CHECK_OPTION(direction_deg >= 0 && direction_deg <= 180);
  CHECK_OPTION_GE(roll_steps, 0);
  CHECK_OPTION(std::isfinite(joint_radius));
  return true;
}

ViewNeighbourhood::ViewNeighbourhood(const Database& db)
    : num_rolls_(std::max<uint32_t>(1, db.num_rolls())) {
  views_.resize(db.num_views());
  for (view_id_t v = 0; v < db.num_views(); ++v) {
    const ViewLabel label = db.label(v);
    ViewInfo& info = views_[v];
    info.direction = label.view_direction;
    info.joints = label.joint_angles;
    info.axis_angle = HandAxisAngle(label);
  }
}

std::vector<SearchPair> ViewNeighbourhood::Near(const Match& previous,
                                                const NeighbourhoodOptions& options) const {
  THROW_CHECK(options.Check());
  std::vector<SearchPair> out;
  if (previous.view_id >= views_.size()) return out;
  const ViewInfo& p = views_[previous.view_id];
  const double cos_max = std::cos(options.direction_deg * M_PI / 180.0);
  const double step = 2 * M_PI / num_rolls_;
  // The previous answer's hand axis in the picture's frame, in the right hand's (unmirrored)
  // frame where both the previous pair and its neighbours live.
  const double target = p.axis_angle + previous.roll * step;
  const int steps = std::min<int>(options.roll_steps, static_cast<int>(num_rolls_ - 1) / 2);
  const double radius2 =
      options.joint_radius >= 0 ? options.joint_radius * options.joint_radius * kNumJointAngles : 0;
  for (size_t v = 0; v < views_.size(); ++v) {
    const ViewInfo& q = views_[v];
    const double dot = double(p.direction[0]) * q.direction[0] +
                       double(p.direction[1]) * q.direction[1] +
                       double(p.direction[2]) * q.direction[2];
    if (v != previous.view_id && dot < cos_max) continue;
    if (options.joint_radius >= 0 && v != previous.view_id) {
      double d2 = 0;
      for (int j = 0; j < kNumJointAngles; ++j) {
        const double d = double(p.joints[j]) - q.joints[j];
        d2 += d * d;
      }
      if (d2 > radius2) continue;
    }
    const int centre = v == previous.view_id
                           ? static_cast<int>(previous.roll)
                           : static_cast<int>(std::lround((target - q.axis_angle) / step));
    std::vector<roll_id_t> rolls;
    for (int d = -steps; d <= steps; ++d) {
      const int r = ((centre + d) % static_cast<int>(num_rolls_) + static_cast<int>(num_rolls_)) %
                    static_cast<int>(num_rolls_);
      rolls.push_back(static_cast<roll_id_t>(r));
    }
    std::sort(rolls.begin(), rolls.end());
    rolls.erase(std::unique(rolls.begin(), rolls.end()), rolls.end());
    for (roll_id_t r : rolls) out.push_back({static_cast<view_id_t>(v), r, previous.hand});
  }
  return out;
}

}  // namespace handdb
