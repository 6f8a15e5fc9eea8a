// The evaluation's metrics (docs/evaluation.md), as pure functions over pose labels so they can
// be tested on hand-made cases: when a database match counts as correct, the rank of the best
// correct match and the paper's Table 1 bins, success@(d, n), root-relative 3D keypoint error and
// its floor over a whole database.
//
// Correctness of a database view (v, r) for a test view, all three must hold:
//  - shape: the joint-vector distance is at most d (JointDistanceDeg below; default the RMS of
//    the 20 joint-angle differences in degrees, d = 15), or, in "same shape" mode (test views of a
//    basic shape, as in the paper), the database shape is that basic shape;
//  - view direction: the angle between the two unit view directions is at most 30 degrees;
//  - roll: the in-plane camera rotation differs by at most 30 degrees (circular). By default the
//    roll difference is measured between the two cameras after the database camera has been
//    turned by the smallest rotation that carries its view direction onto the test's (RollCompare::
//    kAligned): the "camera up rule" of docs/conventions.md changes fast near the hand's forward
//    axis, so comparing the camera_roll numbers of two different directions can be off by tens of
//    degrees there even for cameras that see the same image. With equal directions both modes
//    agree.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "format/view.h"

namespace handdb {

using Vec3 = std::array<double, 3>;

// Distances between two 20-D joint vectors (radians in, degrees out).
enum class JointDistanceKind {
  kRms,   // sqrt(mean_i (a_i - b_i)^2): one number that grows with how many joints differ
  kMax,   // max_i |a_i - b_i|: strict, every joint within d
  kMean,  // mean_i |a_i - b_i|
};
std::string_view JointDistanceKindName(JointDistanceKind kind);
std::optional<JointDistanceKind> ParseJointDistanceKind(std::string_view name);

double JointDistanceDeg(std::span<const float> a, std::span<const float> b, JointDistanceKind kind);

// Angle between two (not necessarily unit) directions, degrees in [0, 180].
double DirectionAngleDeg(const Vec3& a, const Vec3& b);

// |a - b| modulo 2*pi, radians in, degrees out, in [0, 180].
double CircularDifferenceDeg(double a_rad, double b_rad);

// The hand's two reference axes from the hand-model JSON (docs/conventions.md), hand frame.
struct HandAxes {
  Vec3 forward_axis{0, 1, 0};  // wrist -> middle MCP: "up" in a roll-0 image
  Vec3 palm_normal{0, 0, 1};   // out of the palm; -palm_normal is "up" when looking along fingers
};

// A camera of the database or of a test view, as a rotation: unit axes of the image in the hand
// frame (OpenCV: x right, y down, z away from the camera, so z = -view_direction).
struct CameraAxes {
  Vec3 x;
  Vec3 y;
  Vec3 z;
};
// The camera that the conventions' up rule and roll produce for `view_direction` (hand -> camera)
// and `camera_roll` (radians; x' = cos a x - sin a y, y' = sin a x + cos a y in the image).
CameraAxes CameraFromHand(const Vec3& view_direction, double camera_roll, const HandAxes& axes);

// The in-plane rotation between camera b and camera a after b has been turned by the smallest
// rotation taking its optical axis onto a's; degrees in [0, 180]. For equal axes this is the
// circular difference of the two rolls.
double AlignedRollDifferenceDeg(const CameraAxes& a, const CameraAxes& b);

enum class RollCompare {
  kAligned,  // AlignedRollDifferenceDeg of the two cameras (default)
  kLabel,    // CircularDifferenceDeg of the two camera_roll values
};

struct CorrectnessOptions {
  JointDistanceKind joint_distance = JointDistanceKind::kRms;
  double max_joint_distance_deg = 15.0;  // d
  double max_direction_deg = 30.0;
  double max_roll_deg = 30.0;
  RollCompare roll_compare = RollCompare::kAligned;
  // For test views of a basic shape: correct shape = the same basic shape (joint vectors equal
  // within kSameShapeToleranceDeg, max norm) instead of "within d". Test views sampled in the PCA
  // space always use d.
  bool same_shape = false;
  bool Check() const;
};
constexpr double kSameShapeToleranceDeg = 0.01;

// What the metrics need to know about one pose: the label of a (view, roll) or a test view.
struct PoseForEval {
  std::array<float, kNumJointAngles> joint_angles{};
  Vec3 view_direction{0, 0, 1};
  double camera_roll = 0;  // radians
  // Keypoints in a normalised frame (diameter kNormalisedDiameter), px; x, y, z.
  std::array<std::array<float, 3>, kNumKeypoints> keypoints{};
};
// The pose of database view (label, roll angle): camera_roll and keypoints rolled (format/roll.h).
PoseForEval PoseFromLabel(const ViewLabel& label, float roll_angle);

// Per-criterion breakdown, for reports and tests.
struct CorrectnessDetail {
  double joint_distance_deg = 0;
  double direction_deg = 0;
  double roll_deg = 0;
  bool shape_ok = false;
  bool direction_ok = false;
  bool roll_ok = false;
  bool correct() const { return shape_ok && direction_ok && roll_ok; }
};

// Decides correctness. Precomputes the test view's camera so that many database views can be
// checked fast.
class CorrectnessJudge {
 public:
  CorrectnessJudge(const PoseForEval& truth,
                   bool truth_is_basic_shape,
                   const HandAxes& axes,
                   const CorrectnessOptions& options);
  CorrectnessDetail Judge(const PoseForEval& candidate) const;
  bool IsCorrect(const PoseForEval& candidate) const { return Judge(candidate).correct(); }

 private:
  PoseForEval truth_;
  bool use_same_shape_;
  HandAxes axes_;
  CorrectnessOptions options_;
  CameraAxes truth_camera_;
};

// Root-relative 3D keypoint error in units of hand size: both keypoint sets are translated so the
// wrist (keypoint 0) is the origin; the mean Euclidean distance over the other 20 keypoints is
// divided by kNormalisedDiameter (the silhouette diameter both frames are scaled to). 0.1 means a
// mean joint error of a tenth of the hand's extent in the image.
double KeypointError(const std::array<std::array<float, 3>, kNumKeypoints>& a,
                     const std::array<std::array<float, 3>, kNumKeypoints>& b);

using Keypoints = std::array<std::array<float, 3>, kNumKeypoints>;

// The 3D distance from the wrist (keypoint 0) to the middle finger's MCP (keypoint 9, the middle
// knuckle; docs/conventions.md), px of the keypoints' frame. KeypointError * kNormalisedDiameter /
// WristToMiddleMcp(truth) is the same error in units of this length of the true hand, a size
// that does not depend on the view (the hand size of KeypointError is its silhouette's).
double WristToMiddleMcp(const Keypoints& keypoints);

// The smallest KeypointError of a truth over every (view, roll) of a database: the "floor" that
// no retrieval from it can beat. The database's rolls are virtual, so each stored view's
// keypoints are kept once and rolled as RollLabel rolls them; a roll-free lower bound per view (a
// rotation about the optical axis keeps each keypoint's distance from the axis through the wrist
// and its depth) orders the views and ends the scan once no remaining view can beat the best, so
// the result equals the exhaustive minimum.
struct KeypointFloor {
  double error = std::numeric_limits<double>::quiet_NaN();  // hand sizes, as KeypointError
  view_id_t view_id = kInvalidViewId;
  roll_id_t roll = 0;
  uint64_t views_checked = 0;  // stored views whose rolls were all tried
};

class KeypointFloorIndex {
 public:
  // labels: the canonical (roll 0) label of every stored view, index = view id.
  KeypointFloorIndex(std::vector<ViewLabel> labels, uint32_t num_rolls);
  // Thread-safe (const).
  KeypointFloor Floor(const Keypoints& truth) const;
  size_t num_views() const { return labels_.size(); }

 private:
  std::vector<ViewLabel> labels_;
  uint32_t num_rolls_;
  // Per view and keypoint 1..20: distance from the wrist in the image plane, and depth from it.
  std::vector<std::array<float, 2 * (kNumKeypoints - 1)>> invariants_;
};

// ---- Ranks and the paper's Table 1 ----

constexpr int kNumRankBins = 7;
// Upper bounds of the first six bins; the seventh is "> 1024" (including "no correct match").
constexpr std::array<int64_t, kNumRankBins - 1> kRankBinUpper = {1, 4, 16, 64, 256, 1024};
constexpr int64_t kMaxBinnedRank = 1024;
constexpr int64_t kNoCorrectMatch =
    0;  // rank value for "no correct match within the searched depth"
// "1", "2-4", "5-16", "17-64", "65-256", "257-1024", ">1024".
std::string_view RankBinName(int bin);
// Bin index of a 1-based rank; kNoCorrectMatch and ranks > 1024 fall into the last bin.
int RankBin(int64_t rank);

// 1-based rank of the first true flag in `correct` (database matches in increasing D_c), or
// kNoCorrectMatch.
int64_t FirstCorrectRank(std::span<const bool> correct);

struct RankTable {
  std::array<int64_t, kNumRankBins> counts{};
  int64_t total() const;
};
RankTable MakeRankTable(std::span<const int64_t> ranks);

// Fraction of test views whose best correct match has rank in 1..n.
double SuccessAtN(std::span<const int64_t> ranks, int64_t n);

// ---- Summaries ----
struct Summary {
  int64_t count = 0;
  double mean = 0;
  double median = 0;
  double p90 = 0;
  double min = 0;
  double max = 0;
};
// NaN values are skipped (e.g. test views without a match).
Summary Summarise(std::span<const double> values);

// Empirical CDF points (sorted values, fraction <= value), for plots.
std::vector<std::pair<double, double>> EmpiricalCdf(std::span<const double> values);

}  // namespace handdb
