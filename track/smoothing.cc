#include "track/smoothing.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>

#include "track/neighbourhood.h"

namespace handdb {
namespace {

double WrappedAngle(double a) {
  a = std::fmod(std::fabs(a), 2 * M_PI);
  return a > M_PI ? 2 * M_PI - a : a;
}

// The smoothing factor of a first-order low-pass at cut-off `hz` for a step of dt seconds.
double Alpha(double hz, double dt) {
  const double tau = 1.0 / (2 * M_PI * hz);
  return 1.0 / (1.0 + tau / dt);
}

}  // namespace

bool TransitionCosts::Check() const {
  CHECK_OPTION(joint >= 0 && view >= 0 && roll >= 0 && hand >= 0);
  return true;
}

bool KeypointFilterOptions::Check() const {
  CHECK_OPTION(min_cutoff_hz > 0 && beta >= 0 && d_cutoff_hz > 0);
  return true;
}

std::vector<PoseCandidate> CandidatesOf(const std::vector<Match>& matches) {
  std::vector<PoseCandidate> out;
  if (matches.empty()) return out;
  const bool scored = matches.front().score >= 0;
  double best = std::numeric_limits<double>::infinity();
  for (const Match& m : matches) best = std::min(best, scored ? m.score : m.distance);
  for (const Match& m : matches) {
    PoseCandidate c;
    if (scored) {
      c.unary = m.score - best;
    } else {
      c.unary = best > 0 ? m.distance / best - 1 : m.distance;
    }
    c.joints = m.label.joint_angles;
    c.view_direction = m.label.view_direction;
    c.axis_angle = HandAxisAngle(m.label);
    c.hand = m.hand;
    out.push_back(c);
  }
  return out;
}

double TransitionCost(const PoseCandidate& from,
                      const PoseCandidate& to,
                      const TransitionCosts& costs) {
  double j2 = 0;
  for (int j = 0; j < kNumJointAngles; ++j) {
    const double d = double(from.joints[j]) - to.joints[j];
    j2 += d * d;
  }
  const double dot = double(from.view_direction[0]) * to.view_direction[0] +
                     double(from.view_direction[1]) * to.view_direction[1] +
                     double(from.view_direction[2]) * to.view_direction[2];
  const double view = std::acos(std::clamp(dot, -1.0, 1.0));
  return costs.joint * std::sqrt(j2 / kNumJointAngles) + costs.view * view +
         costs.roll * WrappedAngle(to.axis_angle - from.axis_angle) +
         (from.hand != to.hand ? costs.hand : 0.0);
}

std::vector<int> ChooseByDynamicProgramming(const std::vector<std::vector<PoseCandidate>>& frames,
                                            const TransitionCosts& costs) {
  const size_t n = frames.size();
  std::vector<int> choice(n, -1);
  size_t begin = 0;
  while (begin < n) {
    if (frames[begin].empty()) {
      ++begin;
      continue;
    }
    size_t end = begin;
    while (end < n && !frames[end].empty()) ++end;
    // Viterbi over [begin, end): best[t][j] the least cost of a path ending at candidate j of t.
    std::vector<std::vector<double>> best(end - begin);
    std::vector<std::vector<int>> from(end - begin);
    for (size_t t = begin; t < end; ++t) {
      const auto& cands = frames[t];
      auto& b = best[t - begin];
      auto& f = from[t - begin];
      b.assign(cands.size(), 0);
      f.assign(cands.size(), -1);
      for (size_t j = 0; j < cands.size(); ++j) {
        double least = 0;
        if (t > begin) {
          least = std::numeric_limits<double>::infinity();
          const auto& prev = frames[t - 1];
          const auto& pb = best[t - 1 - begin];
          for (size_t i = 0; i < prev.size(); ++i) {
            const double c = pb[i] + TransitionCost(prev[i], cands[j], costs);
            if (c < least) {
              least = c;
              f[j] = static_cast<int>(i);
            }
          }
        }
        b[j] = least + cands[j].unary;
      }
    }
    const auto& last = best.back();
    int j = static_cast<int>(std::min_element(last.begin(), last.end()) - last.begin());
    for (size_t t = end; t-- > begin;) {
      choice[t] = j;
      j = from[t - begin][j];
    }
    begin = end;
  }
  return choice;
}

namespace {

// A keypoint set's coordinates as floats, in order (Point2f and std::array<float, 3> are plain
// floats).
template <typename K>
std::span<const float> Values(const K& k) {
  static_assert(sizeof(K) == sizeof(float) * kNumKeypoints * (sizeof(k[0]) / sizeof(float)));
  return {reinterpret_cast<const float*>(k.data()), sizeof(K) / sizeof(float)};
}
template <typename K>
std::span<float> Values(K& k) {
  return {reinterpret_cast<float*>(k.data()), sizeof(K) / sizeof(float)};
}

}  // namespace

template <typename K>
K KeypointFilter<K>::Filter(const K& raw, double t) {
  const std::span<const float> in = Values(raw);
  K out{};
  const std::span<float> o = Values(out);
  if (!last_t_ || t <= *last_t_) {
    if (!last_t_) {
      for (size_t i = 0; i < kValues; ++i) x_[i] = in[i];
      dx_.fill(0);
    }
    last_t_ = t;
    for (size_t i = 0; i < kValues; ++i) o[i] = static_cast<float>(x_[i]);
    return out;
  }
  const double dt = t - *last_t_;
  last_t_ = t;
  const double ad = Alpha(options_.d_cutoff_hz, dt);
  for (size_t i = 0; i < kValues; ++i) {
    const double d = (in[i] - x_[i]) / dt;
    dx_[i] += ad * (d - dx_[i]);
    const double cutoff = options_.min_cutoff_hz + options_.beta * std::fabs(dx_[i]);
    x_[i] += Alpha(cutoff, dt) * (in[i] - x_[i]);
    o[i] = static_cast<float>(x_[i]);
  }
  return out;
}

template <typename K>
std::vector<std::optional<K>> FilterSequence(const std::vector<std::optional<K>>& keypoints,
                                             const std::vector<double>& times,
                                             const KeypointFilterOptions& options) {
  THROW_CHECK_EQ(keypoints.size(), times.size());
  std::vector<std::optional<K>> out = keypoints;
  if (!options.enabled) return out;
  const size_t n = keypoints.size();
  size_t begin = 0;
  while (begin < n) {
    if (!keypoints[begin]) {
      ++begin;
      continue;
    }
    size_t end = begin;
    while (end < n && keypoints[end]) ++end;
    std::vector<K> forward(end - begin), backward(end - begin);
    KeypointFilter<K> f(options), b(options);
    for (size_t t = begin; t < end; ++t) forward[t - begin] = f.Filter(*keypoints[t], times[t]);
    // Backward in time: the same filter on negated times.
    for (size_t t = end; t-- > begin;) backward[t - begin] = b.Filter(*keypoints[t], -times[t]);
    for (size_t t = begin; t < end; ++t) {
      K avg{};
      const std::span<const float> fw = Values(forward[t - begin]),
                                   bw = Values(backward[t - begin]);
      const std::span<float> a = Values(avg);
      for (size_t i = 0; i < a.size(); ++i) a[i] = (fw[i] + bw[i]) / 2;
      out[t] = avg;
    }
    begin = end;
  }
  return out;
}

template class KeypointFilter<Keypoints2d>;
template class KeypointFilter<Keypoints3d>;
template std::vector<std::optional<Keypoints2d>> FilterSequence(
    const std::vector<std::optional<Keypoints2d>>&,
    const std::vector<double>&,
    const KeypointFilterOptions&);
template std::vector<std::optional<Keypoints3d>> FilterSequence(
    const std::vector<std::optional<Keypoints3d>>&,
    const std::vector<double>&,
    const KeypointFilterOptions&);

}  // namespace handdb
