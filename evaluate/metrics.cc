#include "evaluate/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "format/roll.h"

namespace handdb {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;
// docs/conventions.md: past this |d . forward_axis| the up rule switches to -palm_normal.
constexpr double kUpRuleSwitch = 0.99;

double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 Scale(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
Vec3 Add(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
double Norm(const Vec3& a) { return std::sqrt(Dot(a, a)); }
Vec3 Normalised(const Vec3& a) {
  const double n = Norm(a);
  THROW_CHECK_MSG(n > 0, "zero-length vector");
  return Scale(a, 1.0 / n);
}
// Any unit vector perpendicular to unit vector a.
Vec3 AnyPerpendicular(const Vec3& a) {
  const Vec3 helper = std::abs(a[0]) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  return Normalised(Cross(a, helper));
}
// Rodrigues: rotate v about unit axis k by angle.
Vec3 Rotate(const Vec3& v, const Vec3& k, double angle) {
  const double c = std::cos(angle);
  const double s = std::sin(angle);
  return Add(Add(Scale(v, c), Scale(Cross(k, v), s)), Scale(k, Dot(k, v) * (1 - c)));
}

}  // namespace

std::string_view JointDistanceKindName(JointDistanceKind kind) {
  switch (kind) {
    case JointDistanceKind::kRms:
      return "rms";
    case JointDistanceKind::kMax:
      return "max";
    case JointDistanceKind::kMean:
      return "mean";
  }
  return "?";
}

std::optional<JointDistanceKind> ParseJointDistanceKind(std::string_view name) {
  if (name == "rms") return JointDistanceKind::kRms;
  if (name == "max") return JointDistanceKind::kMax;
  if (name == "mean") return JointDistanceKind::kMean;
  return std::nullopt;
}

double JointDistanceDeg(std::span<const float> a,
                        std::span<const float> b,
                        JointDistanceKind kind) {
  THROW_CHECK_EQ(a.size(), b.size());
  THROW_CHECK(!a.empty());
  double sum = 0;
  double sum_sq = 0;
  double max = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    const double diff = std::abs(static_cast<double>(a[i]) - static_cast<double>(b[i])) * kRadToDeg;
    sum += diff;
    sum_sq += diff * diff;
    max = std::max(max, diff);
  }
  const double n = static_cast<double>(a.size());
  switch (kind) {
    case JointDistanceKind::kRms:
      return std::sqrt(sum_sq / n);
    case JointDistanceKind::kMax:
      return max;
    case JointDistanceKind::kMean:
      return sum / n;
  }
  return max;
}

double DirectionAngleDeg(const Vec3& a, const Vec3& b) {
  // atan2 of |a x b| and a . b is accurate for small and large angles alike.
  return std::atan2(Norm(Cross(a, b)), Dot(a, b)) * kRadToDeg;
}

double CircularDifferenceDeg(double a_rad, double b_rad) {
  return std::abs(std::remainder(a_rad - b_rad, 2.0 * M_PI)) * kRadToDeg;
}

CameraAxes CameraFromHand(const Vec3& view_direction, double camera_roll, const HandAxes& axes) {
  const Vec3 d = Normalised(view_direction);
  const Vec3 forward = Normalised(axes.forward_axis);
  const Vec3 up_source =
      std::abs(Dot(d, forward)) > kUpRuleSwitch ? Scale(Normalised(axes.palm_normal), -1) : forward;
  const Vec3 up = Normalised(Add(up_source, Scale(d, -Dot(up_source, d))));
  const Vec3 z0 = Scale(d, -1);
  const Vec3 y0 = Scale(up, -1);
  const Vec3 x0 = Cross(y0, z0);
  // Image coordinates rotate as x' = c x - s y, y' = s x + c y; the axes rotate the same way.
  const double c = std::cos(camera_roll);
  const double s = std::sin(camera_roll);
  return CameraAxes{Add(Scale(x0, c), Scale(y0, -s)), Add(Scale(x0, s), Scale(y0, c)), z0};
}

double AlignedRollDifferenceDeg(const CameraAxes& a, const CameraAxes& b) {
  const Vec3 axis = Cross(b.z, a.z);
  const double sin_angle = Norm(axis);
  const double cos_angle = Dot(b.z, a.z);
  Vec3 y_b = b.y;
  if (sin_angle > 1e-12) {
    y_b = Rotate(b.y, Scale(axis, 1.0 / sin_angle), std::atan2(sin_angle, cos_angle));
  } else if (cos_angle < 0) {
    // Opposite optical axes: every half turn is a smallest rotation; the choice is arbitrary.
    y_b = Rotate(b.y, AnyPerpendicular(b.z), M_PI);
  }
  const double signed_angle = std::atan2(Dot(Cross(y_b, a.y), a.z), Dot(y_b, a.y));
  return std::abs(signed_angle) * kRadToDeg;
}

bool CorrectnessOptions::Check() const {
  CHECK_OPTION_GE(max_joint_distance_deg, 0.0);
  CHECK_OPTION_GE(max_direction_deg, 0.0);
  CHECK_OPTION_LE(max_direction_deg, 180.0);
  CHECK_OPTION_GE(max_roll_deg, 0.0);
  CHECK_OPTION_LE(max_roll_deg, 180.0);
  return true;
}

PoseForEval PoseFromLabel(const ViewLabel& label, float roll_angle) {
  const ViewLabel rolled = roll_angle == 0.0f ? label : RollLabel(label, roll_angle);
  PoseForEval pose;
  pose.joint_angles = rolled.joint_angles;
  pose.view_direction = {
      rolled.view_direction[0], rolled.view_direction[1], rolled.view_direction[2]};
  pose.camera_roll = rolled.camera_roll;
  pose.keypoints = rolled.keypoints;
  return pose;
}

CorrectnessJudge::CorrectnessJudge(const PoseForEval& truth,
                                   bool truth_is_basic_shape,
                                   const HandAxes& axes,
                                   const CorrectnessOptions& options)
    : truth_(truth),
      use_same_shape_(options.same_shape && truth_is_basic_shape),
      axes_(axes),
      options_(options),
      truth_camera_(CameraFromHand(truth.view_direction, truth.camera_roll, axes)) {
  THROW_CHECK(options.Check());
}

CorrectnessDetail CorrectnessJudge::Judge(const PoseForEval& candidate) const {
  CorrectnessDetail detail;
  detail.joint_distance_deg =
      JointDistanceDeg(truth_.joint_angles, candidate.joint_angles, options_.joint_distance);
  if (use_same_shape_) {
    detail.shape_ok =
        JointDistanceDeg(truth_.joint_angles, candidate.joint_angles, JointDistanceKind::kMax) <=
        kSameShapeToleranceDeg;
  } else {
    detail.shape_ok = detail.joint_distance_deg <= options_.max_joint_distance_deg;
  }
  detail.direction_deg = DirectionAngleDeg(truth_.view_direction, candidate.view_direction);
  detail.direction_ok = detail.direction_deg <= options_.max_direction_deg;
  if (options_.roll_compare == RollCompare::kLabel) {
    detail.roll_deg = CircularDifferenceDeg(truth_.camera_roll, candidate.camera_roll);
  } else {
    detail.roll_deg = AlignedRollDifferenceDeg(
        truth_camera_, CameraFromHand(candidate.view_direction, candidate.camera_roll, axes_));
  }
  detail.roll_ok = detail.roll_deg <= options_.max_roll_deg;
  return detail;
}

double KeypointError(const std::array<std::array<float, 3>, kNumKeypoints>& a,
                     const std::array<std::array<float, 3>, kNumKeypoints>& b) {
  double sum = 0;
  for (int i = 1; i < kNumKeypoints; ++i) {
    double sq = 0;
    for (int c = 0; c < 3; ++c) {
      const double da = static_cast<double>(a[i][c]) - a[0][c];
      const double db = static_cast<double>(b[i][c]) - b[0][c];
      sq += (da - db) * (da - db);
    }
    sum += std::sqrt(sq);
  }
  return sum / (kNumKeypoints - 1) / kNormalisedDiameter;
}

double WristToMiddleMcp(const Keypoints& keypoints) {
  double sq = 0;
  for (int c = 0; c < 3; ++c) {
    const double d = static_cast<double>(keypoints[9][c]) - keypoints[0][c];
    sq += d * d;
  }
  return std::sqrt(sq);
}

namespace {

// Per keypoint 1..20: the in-plane distance from the wrist and the depth relative to it, the two
// numbers a roll leaves unchanged.
std::array<float, 2 * (kNumKeypoints - 1)> RollInvariants(const Keypoints& k) {
  std::array<float, 2 * (kNumKeypoints - 1)> out{};
  for (int i = 1; i < kNumKeypoints; ++i) {
    const double dx = static_cast<double>(k[i][0]) - k[0][0];
    const double dy = static_cast<double>(k[i][1]) - k[0][1];
    out[2 * (i - 1)] = static_cast<float>(std::hypot(dx, dy));
    out[2 * (i - 1) + 1] = static_cast<float>(static_cast<double>(k[i][2]) - k[0][2]);
  }
  return out;
}

// A lower bound of KeypointError between any roll of the view and the truth (|a - b| >=
// ||a_xy| - |b_xy|| per keypoint, with the depths unchanged).
double RollFreeBound(const std::array<float, 2 * (kNumKeypoints - 1)>& a,
                     const std::array<float, 2 * (kNumKeypoints - 1)>& b) {
  double sum = 0;
  for (int i = 0; i < kNumKeypoints - 1; ++i) {
    const double dr = static_cast<double>(a[2 * i]) - b[2 * i];
    const double dz = static_cast<double>(a[2 * i + 1]) - b[2 * i + 1];
    sum += std::sqrt(dr * dr + dz * dz);
  }
  return sum / (kNumKeypoints - 1) / kNormalisedDiameter;
}

// The invariants are floats and the rolled keypoints are rounded to floats, so the bound may
// exceed the computed error by a few float ulps of the coordinates; a view is skipped only when
// its bound is above the best by more than this (hand sizes: 0.002 px of mean joint distance).
constexpr double kBoundSlack = 1e-5;

}  // namespace

KeypointFloorIndex::KeypointFloorIndex(std::vector<ViewLabel> labels, uint32_t num_rolls)
    : labels_(std::move(labels)), num_rolls_(num_rolls) {
  THROW_CHECK_GE(num_rolls_, 1u);
  invariants_.reserve(labels_.size());
  for (const ViewLabel& l : labels_) invariants_.push_back(RollInvariants(l.keypoints));
}

KeypointFloor KeypointFloorIndex::Floor(const Keypoints& truth) const {
  KeypointFloor best;
  if (labels_.empty()) return best;
  const auto truth_inv = RollInvariants(truth);
  std::vector<std::pair<double, view_id_t>> order(labels_.size());
  for (size_t v = 0; v < labels_.size(); ++v) {
    order[v] = {RollFreeBound(invariants_[v], truth_inv), static_cast<view_id_t>(v)};
  }
  std::sort(order.begin(), order.end());
  double best_error = std::numeric_limits<double>::infinity();
  for (const auto& [bound, v] : order) {
    if (bound > best_error + kBoundSlack) break;
    for (roll_id_t r = 0; r < num_rolls_; ++r) {
      // The keypoints of (v, r) exactly as a search's match label carries them.
      const Keypoints rolled =
          r == 0 ? labels_[v].keypoints : RollLabel(labels_[v], RollAngle(r, num_rolls_)).keypoints;
      const double e = KeypointError(truth, rolled);
      // Ties go to the smallest (view, roll), so the answer does not depend on the scan order.
      if (e < best_error ||
          (e == best_error && std::make_pair(v, r) < std::make_pair(best.view_id, best.roll))) {
        best_error = e;
        best.view_id = v;
        best.roll = r;
      }
    }
    ++best.views_checked;
  }
  best.error = best_error;
  return best;
}

std::string_view RankBinName(int bin) {
  static constexpr std::array<std::string_view, kNumRankBins> kNames = {
      "1", "2-4", "5-16", "17-64", "65-256", "257-1024", ">1024"};
  THROW_CHECK(bin >= 0 && bin < kNumRankBins);
  return kNames[bin];
}

int RankBin(int64_t rank) {
  THROW_CHECK_GE(rank, 0);
  if (rank == kNoCorrectMatch) return kNumRankBins - 1;
  for (int i = 0; i < kNumRankBins - 1; ++i) {
    if (rank <= kRankBinUpper[i]) return i;
  }
  return kNumRankBins - 1;
}

int64_t FirstCorrectRank(std::span<const bool> correct) {
  for (size_t i = 0; i < correct.size(); ++i) {
    if (correct[i]) return static_cast<int64_t>(i) + 1;
  }
  return kNoCorrectMatch;
}

int64_t RankTable::total() const {
  int64_t sum = 0;
  for (int64_t c : counts) sum += c;
  return sum;
}

RankTable MakeRankTable(std::span<const int64_t> ranks) {
  RankTable table;
  for (int64_t rank : ranks) ++table.counts[RankBin(rank)];
  return table;
}

double SuccessAtN(std::span<const int64_t> ranks, int64_t n) {
  if (ranks.empty()) return 0;
  int64_t hits = 0;
  for (int64_t rank : ranks) {
    if (rank != kNoCorrectMatch && rank <= n) ++hits;
  }
  return static_cast<double>(hits) / static_cast<double>(ranks.size());
}

namespace {
// Linear interpolation between order statistics (the "type 7" quantile of R and numpy).
double Quantile(const std::vector<double>& sorted, double q) {
  const double pos = q * static_cast<double>(sorted.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(pos));
  const size_t hi = std::min(lo + 1, sorted.size() - 1);
  const double t = pos - static_cast<double>(lo);
  return sorted[lo] + (sorted[hi] - sorted[lo]) * t;
}
}  // namespace

Summary Summarise(std::span<const double> values) {
  std::vector<double> sorted;
  sorted.reserve(values.size());
  for (double v : values) {
    if (!std::isnan(v)) sorted.push_back(v);
  }
  Summary s;
  s.count = static_cast<int64_t>(sorted.size());
  if (sorted.empty()) {
    s.mean = s.median = s.p90 = s.min = s.max = std::numeric_limits<double>::quiet_NaN();
    return s;
  }
  std::sort(sorted.begin(), sorted.end());
  double sum = 0;
  for (double v : sorted) sum += v;
  s.mean = sum / static_cast<double>(sorted.size());
  s.median = Quantile(sorted, 0.5);
  s.p90 = Quantile(sorted, 0.9);
  s.min = sorted.front();
  s.max = sorted.back();
  return s;
}

std::vector<std::pair<double, double>> EmpiricalCdf(std::span<const double> values) {
  std::vector<double> sorted;
  for (double v : values) {
    if (!std::isnan(v)) sorted.push_back(v);
  }
  std::sort(sorted.begin(), sorted.end());
  std::vector<std::pair<double, double>> cdf;
  cdf.reserve(sorted.size());
  for (size_t i = 0; i < sorted.size(); ++i) {
    cdf.emplace_back(sorted[i], static_cast<double>(i + 1) / static_cast<double>(sorted.size()));
  }
  return cdf;
}

}  // namespace handdb
