#include "pose/fit.h"

#include <ceres/ceres.h>
#include <ceres/cubic_interpolation.h>
#include <ceres/rotation.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <vector>

#include "pose/fit_kinematics.h"
#include "pose/fit_landmark_cost.h"

namespace handdb {
namespace {

// Ceres' quaternion order: w, x, y, z.
using Quaternion = std::array<double, 4>;

Quaternion QuaternionOf(const Mat3d& rotation) {
  Quaternion q;
  ceres::RotationMatrixToQuaternion(ceres::RowMajorAdapter3x3(&rotation[0][0]), q.data());
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (double& v : q) v /= n;
  return q;
}

Mat3d RotationOf(const Quaternion& q) {
  Mat3d r;
  ceres::QuaternionToRotation(q.data(), ceres::RowMajorAdapter3x3(&r[0][0]));
  return r;
}

// (cam_from_hand * (point_in_hand - look_at)).xy: the rig's orthographic projection, in hand
// units, before the normalised frame's scale and shift.
std::array<double, 2> ProjectXY(const Mat3d& cam_from_hand, const Vec3d& look_at, const Vec3d& p) {
  const Vec3d d{p[0] - look_at[0], p[1] - look_at[1], p[2] - look_at[2]};
  std::array<double, 2> out;
  for (int r = 0; r < 2; ++r) {
    out[r] = cam_from_hand[r][0] * d[0] + cam_from_hand[r][1] * d[1] + cam_from_hand[r][2] * d[2];
  }
  return out;
}

constexpr int kDigitDofs = FitKinematics::kDigitDofs;
constexpr int kNumDigits = FitKinematics::kNumDigits;

// The fit's parameter blocks: the joint angles one block per digit (a keypoint's residual then
// differentiates with respect to its own digit's 4 angles, not all 20), the rotation, the
// projection's scale and shift. The digits' blocks are consecutive slices of one JointVector.
struct PoseBlocks {
  double* joints;  // kNumJointAngles, DOF order
  double* cam_from_hand;
  double* scale;
  double* shift;

  double* digit(int d) const { return joints + d * kDigitDofs; }

  // Every block, in the order of the Jacobian's columns: the joints, the rotation, scale, shift.
  void AddTo(ceres::Problem* problem) const {
    for (int d = 0; d < kNumDigits; ++d) problem->AddParameterBlock(digit(d), kDigitDofs);
    problem->AddParameterBlock(cam_from_hand, 4);
    problem->AddParameterBlock(scale, 1);
    problem->AddParameterBlock(shift, 2);
  }
};

// The residual block of landmark k over its blocks (pose/fit_landmark_cost.h).
ceres::ResidualBlockId AddLandmarkBlock(ceres::Problem* problem,
                                        ceres::LossFunction* loss,
                                        const PoseBlocks& blocks,
                                        const FitKinematics* kinematics,
                                        int keypoint,
                                        const Vec3d& look_at,
                                        const Point2f& landmark,
                                        double inverse_sigma) {
  auto* cost = new fit_internal::LandmarkCost(
      fit_internal::LandmarkResidual(kinematics, keypoint, look_at, landmark, inverse_sigma));
  if (keypoint == 0) {
    return problem->AddResidualBlock(cost, loss, blocks.cam_from_hand, blocks.scale, blocks.shift);
  }
  return problem->AddResidualBlock(cost,
                                   loss,
                                   blocks.digit(FitKinematics::DigitOf(keypoint)),
                                   blocks.cam_from_hand,
                                   blocks.scale,
                                   blocks.shift);
}

// A digit's joints near the candidate's: per joint (angle - start) / sigma.
class DigitPrior {
 public:
  DigitPrior(const double* start, double joint_sigma) : inverse_sigma_(1.0 / joint_sigma) {
    std::copy(start, start + kDigitDofs, start_.begin());
  }

  template <typename T>
  bool operator()(const T* digit, T* residuals) const {
    for (int i = 0; i < kDigitDofs; ++i) residuals[i] = (digit[i] - T(start_[i])) * inverse_sigma_;
    return true;
  }

  static ceres::CostFunction* Create(const double* start, double joint_sigma) {
    return new ceres::AutoDiffCostFunction<DigitPrior, kDigitDofs, kDigitDofs>(
        new DigitPrior(start, joint_sigma));
  }

 private:
  std::array<double, kDigitDofs> start_{};
  double inverse_sigma_;
};

// The rotation near the candidate's: the rotation from the candidate's camera to the fitted one
// as 2 sin(angle / 2) * axis / sigma (the angle-axis vector to first order, and smooth at zero).
class RotationPrior {
 public:
  RotationPrior(const Quaternion& cam_from_hand, double rotation_sigma)
      : hand_from_cam_{cam_from_hand[0], -cam_from_hand[1], -cam_from_hand[2], -cam_from_hand[3]},
        inverse_sigma_(1.0 / rotation_sigma) {}

  template <typename T>
  bool operator()(const T* cam_from_hand, T* residuals) const {
    const T start_inverse[4] = {
        T(hand_from_cam_[0]), T(hand_from_cam_[1]), T(hand_from_cam_[2]), T(hand_from_cam_[3])};
    T delta[4];
    ceres::QuaternionProduct(start_inverse, cam_from_hand, delta);
    // q and -q are the same rotation: measure from the one nearer the identity.
    const double sign = delta[0] < T(0.0) ? -2.0 : 2.0;
    for (int i = 0; i < 3; ++i) residuals[i] = delta[i + 1] * (sign * inverse_sigma_);
    return true;
  }

  static ceres::CostFunction* Create(const Quaternion& cam_from_hand, double rotation_sigma) {
    return new ceres::AutoDiffCostFunction<RotationPrior, 3, 4>(
        new RotationPrior(cam_from_hand, rotation_sigma));
  }

 private:
  Quaternion hand_from_cam_;
  double inverse_sigma_;
};

// One pair of keypoints' change in depth (the camera's z), in the rig's wrist-to-middle-knuckle
// lengths, minus the evidence's, over sigma. The projection's scale and shift do not enter: the
// pose and the rotation alone set how a bone turns towards or away from the camera.
class DepthResidual {
 public:
  DepthResidual(const FitKinematics* kinematics,
                int keypoint,
                int reference,
                double target,
                double inverse_length,
                double inverse_sigma)
      : kinematics_(kinematics),
        keypoint_(keypoint),
        reference_(reference),
        target_(target),
        inverse_length_(inverse_length),
        inverse_sigma_(inverse_sigma) {}

  // `digit`: keypoint k's digit's joints, which the reference (the wrist or a keypoint of the same
  // digit) depends on too.
  template <typename T>
  bool operator()(const T* digit, const T* cam_from_hand, T* residual) const {
    T point[3], reference[3];
    kinematics_->KeypointOfDigit(digit, keypoint_, point);
    kinematics_->KeypointOfDigit(
        reference_ == 0 ? static_cast<const T*>(nullptr) : digit, reference_, reference);
    for (int r = 0; r < 3; ++r) point[r] -= reference[r];
    T in_cam[3];
    ceres::UnitQuaternionRotatePoint(cam_from_hand, point, in_cam);
    residual[0] = (in_cam[2] * inverse_length_ - T(target_)) * inverse_sigma_;
    return true;
  }

  static ceres::CostFunction* Create(const FitKinematics* kinematics,
                                     int keypoint,
                                     int reference,
                                     double target,
                                     double inverse_length,
                                     double inverse_sigma) {
    return new ceres::AutoDiffCostFunction<DepthResidual, 1, kDigitDofs, 4>(
        new DepthResidual(kinematics, keypoint, reference, target, inverse_length, inverse_sigma));
  }

 private:
  const FitKinematics* kinematics_;
  int keypoint_;
  int reference_;
  double target_;
  double inverse_length_;
  double inverse_sigma_;
};

// Where the bone that ends at keypoint k starts (docs/conventions.md order: each digit's base
// hangs from the wrist, every other keypoint from the one before it).
int ParentKeypoint(int k) { return k % 4 == 1 ? 0 : k - 1; }

// The depth term's residual blocks (PoseFitOptions), one per pair of keypoints with a weight.
std::vector<ceres::ResidualBlockId> AddDepthBlocks(ceres::Problem* problem,
                                                   const FitKinematics& kinematics,
                                                   const HandRig& rig,
                                                   const PoseFitEvidence& evidence,
                                                   const PoseFitOptions& options,
                                                   double* joints,
                                                   double* cam_from_hand) {
  std::vector<ceres::ResidualBlockId> blocks;
  if (!evidence.has_landmarks || !evidence.has_depths || !(options.depth_weight > 0)) {
    return blocks;
  }
  // The metacarpals carry no joint angle: this length is the rig's, whatever the pose.
  const HandKeypoints3d rest = rig.Keypoints3d(JointVector{});
  const double length =
      std::hypot(rest[9][0] - rest[0][0], rest[9][1] - rest[0][1], rest[9][2] - rest[0][2]);
  for (int k = 1; k < kNumKeypoints; ++k) {
    const int reference = options.depth_from_wrist ? 0 : ParentKeypoint(k);
    const double w =
        std::min(evidence.weights[k], evidence.weights[reference]) * options.depth_weight;
    if (!(w > 0)) continue;
    ceres::LossFunction* loss = new ceres::ScaledLoss(
        new ceres::CauchyLoss(options.depth_loss_scale), w, ceres::TAKE_OWNERSHIP);
    blocks.push_back(problem->AddResidualBlock(
        DepthResidual::Create(&kinematics,
                              k,
                              reference,
                              double{evidence.depths[k]} - evidence.depths[reference],
                              1.0 / length,
                              1.0 / options.depth_sigma),
        loss,
        joints + FitKinematics::DigitOf(k) * kDigitDofs,
        cam_from_hand));
  }
  return blocks;
}

// The value part of a scalar: a Jet's value, or the double itself.
inline double ValueOf(double x) { return x; }
template <typename J>
double ValueOf(const J& x) {
  return x.a;
}

// Geman-McClure in residual form: r for small r, bounded by `scale` for large r, smooth at 0.
template <typename T>
T Bounded(const T& r, double scale) {
  using std::sqrt;
  return r / sqrt(T(1.0) + (r * r) * (1.0 / (scale * scale)));
}

// The silhouette term's data (PoseFitOptions), shared by its blocks: the capsules, the two fields
// and their interpolators, the outline and each part's weight. Each capsule's samples are a block
// of their own over its digits' angles (a finger link's Jets carry 11 derivatives, not 27); the
// outline's points are one block over every parameter, since each reads whichever capsule is
// nearest.
class SilhouetteTerm {
 public:
  // Samples along each capsule: a third of the way in from each end and the middle, on the axis
  // and on both sides.
  static constexpr double kAlong[3] = {1.0 / 6, 0.5, 5.0 / 6};

  SilhouetteTerm(const FitKinematics* kinematics,
                 std::vector<HandCapsule> capsules,
                 const Vec3d& look_at,
                 std::shared_ptr<const SilhouetteFields> fields,
                 bool mirrored,
                 const PoseFitOptions& options)
      : kinematics_(kinematics),
        capsules_(std::move(capsules)),
        look_at_(look_at),
        fields_(std::move(fields)),
        mirror_(mirrored ? -1.0 : 1.0),
        hand_grid_(fields_->outside_hand.data(), 0, fields_->size, 0, fields_->size),
        edge_grid_(fields_->edges.data(), 0, fields_->size, 0, fields_->size),
        hand_field_(hand_grid_),
        edge_field_(edge_grid_),
        inverse_sigma_(1.0 / options.silhouette_sigma_px),
        loss_scale_(options.silhouette_loss_scale) {
    int outline_capsules = 0;
    for (const HandCapsule& c : capsules_) outline_capsules += c.outline ? 1 : 0;
    const int num_inside = static_cast<int>(capsules_.size()) * 3 * 3;
    const int num_edges = outline_capsules * 3 * 2;
    const int num_cover = static_cast<int>(fields_->outline.size());
    inside_weight_ = std::sqrt(options.inside_weight / num_inside);
    edge_weight_ = num_edges > 0 ? std::sqrt(options.edge_weight / num_edges) : 0;
    cover_weight_ = num_cover > 0 ? std::sqrt(options.cover_weight / num_cover) : 0;
    for (const Point2f& p : fields_->outline) outline_.push_back({mirror_ * p.x, double(p.y)});
  }

  const std::vector<HandCapsule>& capsules() const { return capsules_; }
  int num_outline() const { return static_cast<int>(outline_.size()); }
  static int NumCapsuleResiduals(const HandCapsule& c) { return c.outline ? 3 * 3 + 3 * 2 : 3 * 3; }

  // Keypoint k in the normalised frame, from its digit's angles (the wrist's from none).
  template <typename T>
  void Project(
      const T* digit, int k, const T* cam_from_hand, const T* scale, const T* shift, T* xy) const {
    T point[3];
    kinematics_->KeypointOfDigit(digit, k, point);
    for (int r = 0; r < 3; ++r) point[r] -= T(look_at_[r]);
    T in_cam[3];
    ceres::UnitQuaternionRotatePoint(cam_from_hand, point, in_cam);
    for (int r = 0; r < 2; ++r) xy[r] = scale[0] * in_cam[r] + shift[r];
  }

  // Capsule c's samples from its end points a and b: points on its axis and sides outside the
  // hand's region, and (an outline capsule) its sides away from the nearest edge.
  template <typename T>
  void CapsuleSamples(int c, const T* a, const T* b, const T* scale, T* residuals) const {
    using std::sqrt;
    const HandCapsule& capsule = capsules_[c];
    const T radius = scale[0] * capsule.radius;
    const T dx = b[0] - a[0], dy = b[1] - a[1];
    // A link seen end-on has no direction in the picture: a tiny length keeps its normal
    // finite (its sides are then any two opposite points of its disc).
    const T length = sqrt(dx * dx + dy * dy + T(1e-6));
    const T nx = -dy / length * radius, ny = dx / length * radius;
    T* inside = residuals;
    T* edges = residuals + 3 * 3;
    for (const double t : kAlong) {
      const T cx = a[0] + t * dx, cy = a[1] + t * dy;
      *inside++ = Read(hand_field_, cx, cy) * inside_weight_;
      *inside++ = Read(hand_field_, cx + nx, cy + ny) * inside_weight_;
      *inside++ = Read(hand_field_, cx - nx, cy - ny) * inside_weight_;
      if (capsule.outline) {
        *edges++ = Read(edge_field_, cx + nx, cy + ny) * edge_weight_;
        *edges++ = Read(edge_field_, cx - nx, cy - ny) * edge_weight_;
      }
    }
  }

  // The outline's points outside every capsule, each its distance from the nearest one.
  template <typename T>
  void Cover(const T* const* digits,
             const T* cam_from_hand,
             const T* scale,
             const T* shift,
             T* residuals) const {
    using std::sqrt;
    // Which capsule is nearest is decided on values; the residual and its derivatives are that
    // capsule's (the minimum's derivative where it is differentiable), so only the keypoints of
    // the nearest capsules are posed with derivatives.
    double values[kNumKeypoints][2];
    {
      double digit_values[kNumDigits][kDigitDofs];
      for (int d = 0; d < kNumDigits; ++d) {
        for (int i = 0; i < kDigitDofs; ++i) digit_values[d][i] = ValueOf(digits[d][i]);
      }
      double q[4], s = ValueOf(scale[0]), t[2] = {ValueOf(shift[0]), ValueOf(shift[1])};
      for (int i = 0; i < 4; ++i) q[i] = ValueOf(cam_from_hand[i]);
      for (int k = 0; k < kNumKeypoints; ++k) {
        Project(digit_values[FitKinematics::DigitOf(k)], k, q, &s, t, values[k]);
      }
    }
    T xy[kNumKeypoints][2];
    bool posed[kNumKeypoints] = {};
    auto keypoint = [&](int k) -> const T* {
      if (!posed[k]) {
        Project(digits[FitKinematics::DigitOf(k)], k, cam_from_hand, scale, shift, xy[k]);
        posed[k] = true;
      }
      return xy[k];
    };
    const double scale_value = ValueOf(scale[0]);
    for (const std::array<double, 2>& q : outline_) {
      int nearest = 0;
      double best = std::numeric_limits<double>::infinity();
      for (size_t i = 0; i < capsules_.size(); ++i) {
        const double d = OutsideCapsule(capsules_[i], values, scale_value, q);
        if (d < best) {
          best = d;
          nearest = static_cast<int>(i);
        }
      }
      if (best <= 0) {
        *residuals++ = T(0.0);
        continue;
      }
      const HandCapsule& c = capsules_[nearest];
      const T* a = keypoint(c.from);
      const T* b = keypoint(c.to);
      const T dx = b[0] - a[0], dy = b[1] - a[1];
      const T ex = T(q[0]) - a[0], ey = T(q[1]) - a[1];
      T t = (ex * dx + ey * dy) / (dx * dx + dy * dy + T(1e-9));
      if (t < T(0.0)) t = T(0.0);
      if (t > T(1.0)) t = T(1.0);
      const T fx = ex - t * dx, fy = ey - t * dy;
      const T distance = sqrt(fx * fx + fy * fy + T(1e-9)) - scale[0] * c.radius;
      *residuals++ = Bounded(distance * inverse_sigma_, loss_scale_) * cover_weight_;
    }
  }

 private:
  using Grid = ceres::Grid2D<float, 1>;
  using Field = ceres::BiCubicInterpolator<Grid>;

  // The field at normalised (x, y), over sigma and bounded.
  template <typename T>
  T Read(const Field& field, const T& x, const T& y) const {
    const T col = (x * mirror_ - fields_->origin_px) / fields_->cell_px;
    const T row = (y - fields_->origin_px) / fields_->cell_px;
    T value;
    field.Evaluate(row, col, &value);
    return Bounded(value * inverse_sigma_, loss_scale_);
  }

  static double OutsideCapsule(const HandCapsule& c,
                               const double (&xy)[kNumKeypoints][2],
                               double scale,
                               const std::array<double, 2>& q) {
    const double ax = xy[c.from][0], ay = xy[c.from][1];
    const double dx = xy[c.to][0] - ax, dy = xy[c.to][1] - ay;
    const double ex = q[0] - ax, ey = q[1] - ay;
    const double t = std::clamp((ex * dx + ey * dy) / (dx * dx + dy * dy + 1e-9), 0.0, 1.0);
    return std::hypot(ex - t * dx, ey - t * dy) - scale * c.radius;
  }

  const FitKinematics* kinematics_;
  std::vector<HandCapsule> capsules_;
  Vec3d look_at_;
  std::shared_ptr<const SilhouetteFields> fields_;
  double mirror_;
  Grid hand_grid_;
  Grid edge_grid_;
  Field hand_field_;
  Field edge_field_;
  double inverse_sigma_;
  double loss_scale_;
  std::vector<std::array<double, 2>> outline_;  // in the fitted (possibly mirrored) frame
  double inside_weight_ = 0;
  double edge_weight_ = 0;
  double cover_weight_ = 0;
};

// The samples (SilhouetteTerm::CapsuleSamples) of the capsules whose end points are the wrist
// and one digit's keypoints, over that digit's angles; or of a capsule across two digits (the
// strut over the knuckles), over both digits' angles. Each keypoint is posed once per block.
class CapsuleResidual {
 public:
  CapsuleResidual(std::shared_ptr<const SilhouetteTerm> term,
                  std::vector<int> capsules,
                  std::vector<int> keypoints)
      : term_(std::move(term)), capsules_(std::move(capsules)), keypoints_(std::move(keypoints)) {}

  int num_residuals() const {
    int n = 0;
    for (const int c : capsules_) n += SilhouetteTerm::NumCapsuleResiduals(term_->capsules()[c]);
    return n;
  }

  template <typename T>
  bool operator()(
      const T* digit, const T* cam_from_hand, const T* scale, const T* shift, T* residuals) const {
    const T* digits[2] = {digit, digit};
    return Samples(digits, cam_from_hand, scale, shift, residuals);
  }

  template <typename T>
  bool operator()(const T* first_digit,
                  const T* second_digit,
                  const T* cam_from_hand,
                  const T* scale,
                  const T* shift,
                  T* residuals) const {
    const T* digits[2] = {first_digit, second_digit};
    return Samples(digits, cam_from_hand, scale, shift, residuals);
  }

  // Adds the silhouette's capsule blocks: one per digit (its links and the strut from the wrist
  // to its base), and one per capsule whose end points lie in two digits.
  static std::vector<ceres::ResidualBlockId> Add(ceres::Problem* problem,
                                                 const std::shared_ptr<const SilhouetteTerm>& term,
                                                 const PoseBlocks& blocks) {
    std::vector<ceres::ResidualBlockId> ids;
    const std::vector<HandCapsule>& capsules = term->capsules();
    std::vector<bool> added(capsules.size(), false);
    for (int d = 0; d < kNumDigits; ++d) {
      auto in_digit = [d](int k) { return k == 0 || FitKinematics::DigitOf(k) == d; };
      std::vector<int> own;
      std::vector<int> keypoints;
      for (int c = 0; c < static_cast<int>(capsules.size()); ++c) {
        if (!in_digit(capsules[c].from) || !in_digit(capsules[c].to)) continue;
        own.push_back(c);
        added[c] = true;
        for (const int k : {capsules[c].from, capsules[c].to}) {
          if (std::find(keypoints.begin(), keypoints.end(), k) == keypoints.end()) {
            keypoints.push_back(k);
          }
        }
      }
      if (own.empty()) continue;
      auto* functor = new CapsuleResidual(term, std::move(own), std::move(keypoints));
      const int n = functor->num_residuals();
      ids.push_back(problem->AddResidualBlock(
          new ceres::AutoDiffCostFunction<CapsuleResidual, ceres::DYNAMIC, kDigitDofs, 4, 1, 2>(
              functor, n),
          nullptr,
          blocks.digit(d),
          blocks.cam_from_hand,
          blocks.scale,
          blocks.shift));
    }
    for (int c = 0; c < static_cast<int>(capsules.size()); ++c) {
      if (added[c]) continue;
      // Two digits (neither end is the wrist, or the digit blocks above would hold it): the
      // first digit's keypoint reads the first block, the second's the second.
      const int first = FitKinematics::DigitOf(capsules[c].from);
      const int second = FitKinematics::DigitOf(capsules[c].to);
      auto* functor = new CapsuleResidual(term, {c}, {capsules[c].from, capsules[c].to});
      const int n = functor->num_residuals();
      ids.push_back(problem->AddResidualBlock(new ceres::AutoDiffCostFunction<CapsuleResidual,
                                                                              ceres::DYNAMIC,
                                                                              kDigitDofs,
                                                                              kDigitDofs,
                                                                              4,
                                                                              1,
                                                                              2>(functor, n),
                                              nullptr,
                                              blocks.digit(first),
                                              blocks.digit(second),
                                              blocks.cam_from_hand,
                                              blocks.scale,
                                              blocks.shift));
    }
    return ids;
  }

 private:
  // digits[0] poses the block's first keypoint's digit, digits[1] every other keypoint's (the
  // same block in a one-digit block).
  template <typename T>
  bool Samples(const T* const (&digits)[2],
               const T* cam_from_hand,
               const T* scale,
               const T* shift,
               T* residuals) const {
    T xy[kNumKeypoints][2];
    for (size_t i = 0; i < keypoints_.size(); ++i) {
      term_->Project(
          digits[i == 0 ? 0 : 1], keypoints_[i], cam_from_hand, scale, shift, xy[keypoints_[i]]);
    }
    for (const int c : capsules_) {
      const HandCapsule& capsule = term_->capsules()[c];
      term_->CapsuleSamples(c, xy[capsule.from], xy[capsule.to], scale, residuals);
      residuals += SilhouetteTerm::NumCapsuleResiduals(capsule);
    }
    return true;
  }

  std::shared_ptr<const SilhouetteTerm> term_;
  std::vector<int> capsules_;   // indices into term_->capsules()
  std::vector<int> keypoints_;  // their end points, each once
};

// The outline's points (SilhouetteTerm::Cover), over every parameter.
class CoverResidual {
 public:
  explicit CoverResidual(std::shared_ptr<const SilhouetteTerm> term) : term_(std::move(term)) {}

  template <typename T>
  bool operator()(const T* thumb,
                  const T* index,
                  const T* middle,
                  const T* ring,
                  const T* little,
                  const T* cam_from_hand,
                  const T* scale,
                  const T* shift,
                  T* residuals) const {
    const T* digits[kNumDigits] = {thumb, index, middle, ring, little};
    term_->Cover(digits, cam_from_hand, scale, shift, residuals);
    return true;
  }

  static ceres::ResidualBlockId Add(ceres::Problem* problem,
                                    const std::shared_ptr<const SilhouetteTerm>& term,
                                    const PoseBlocks& blocks) {
    return problem->AddResidualBlock(
        new ceres::AutoDiffCostFunction<CoverResidual,
                                        ceres::DYNAMIC,
                                        kDigitDofs,
                                        kDigitDofs,
                                        kDigitDofs,
                                        kDigitDofs,
                                        kDigitDofs,
                                        4,
                                        1,
                                        2>(new CoverResidual(term), term->num_outline()),
        nullptr,
        blocks.digit(0),
        blocks.digit(1),
        blocks.digit(2),
        blocks.digit(3),
        blocks.digit(4),
        blocks.cam_from_hand,
        blocks.scale,
        blocks.shift);
  }

 private:
  std::shared_ptr<const SilhouetteTerm> term_;
};

// The silhouette term's blocks: one per capsule, and the outline's (when it has points).
std::vector<ceres::ResidualBlockId> AddSilhouetteBlocks(
    ceres::Problem* problem,
    const FitKinematics& kinematics,
    const HandRig& rig,
    std::shared_ptr<const SilhouetteFields> fields,
    bool mirrored,
    const PoseFitOptions& options,
    const PoseBlocks& blocks) {
  const auto term = std::make_shared<const SilhouetteTerm>(
      &kinematics, HandCapsules(rig), rig.look_at(), std::move(fields), mirrored, options);
  std::vector<ceres::ResidualBlockId> ids = CapsuleResidual::Add(problem, term, blocks);
  if (term->num_outline() > 0) ids.push_back(CoverResidual::Add(problem, term, blocks));
  return ids;
}

Status InvalidArgument(const std::string& message) {
  return Status(StatusCode::kInvalidArgument, "pose fit: " + message);
}

bool Finite(const Point2f& p) { return std::isfinite(p.x) && std::isfinite(p.y); }

std::string PointText(const Point2f& p) {
  std::ostringstream os;
  os << "(" << p.x << ", " << p.y << ")";
  return os.str();
}

// Every landmark and weight finite, weights >= 0; the number of landmarks that count.
Result<int> CheckEvidence(const PoseFitEvidence& evidence) {
  if (!evidence.has_landmarks) return 0;
  int used = 0;
  for (int k = 0; k < kNumKeypoints; ++k) {
    const float w = evidence.weights[k];
    if (!std::isfinite(w) || w < 0) {
      return InvalidArgument("landmark " + std::to_string(k) + ": weight " + std::to_string(w) +
                             " is not a finite number >= 0");
    }
    if (!Finite(evidence.landmarks_px[k])) {
      return InvalidArgument("landmark " + std::to_string(k) + " is " +
                             PointText(evidence.landmarks_px[k]) + ": not finite");
    }
    if (w > 0) ++used;
    if (evidence.has_depths && !std::isfinite(evidence.depths[k])) {
      return InvalidArgument("landmark " + std::to_string(k) + ": depth " +
                             std::to_string(evidence.depths[k]) + " is not finite");
    }
  }
  return used;
}

// The start's camera and the scale and shift that carry its projection onto the candidate's
// stored keypoints (least squares over the 21 keypoints; the rotation is the label's own).
struct StartFrame {
  JointVector joints{};
  Mat3d cam_from_hand{};
  double scale = 0;
  std::array<double, 2> shift{};
  double alignment_rms_px = 0;
};

Result<StartFrame> MakeStartFrame(const HandRig& rig, const PoseFitStart& start) {
  StartFrame frame;
  frame.joints = start.joints;
  for (int i = 0; i < kNumJointAngles; ++i) {
    if (!std::isfinite(frame.joints[i])) {
      return InvalidArgument("start joint " + std::to_string(i) + " is not finite");
    }
  }
  rig.limits().Clamp(&frame.joints);
  if (!std::isfinite(start.roll)) return InvalidArgument("start roll is not finite");
  auto cam_from_hand = CamFromHand(rig, start.view_direction, start.roll);
  if (!cam_from_hand.ok()) return InvalidArgument("start: " + cam_from_hand.status().message());
  frame.cam_from_hand = *cam_from_hand;

  const HandKeypoints3d points = rig.Keypoints3d(frame.joints);
  std::array<std::array<double, 2>, kNumKeypoints> projected;
  double mean_p[2] = {0, 0}, mean_k[2] = {0, 0};
  for (int k = 0; k < kNumKeypoints; ++k) {
    const Point2f& kp = start.keypoints_normalised[k];
    if (!Finite(kp)) {
      return InvalidArgument("start keypoint " + std::to_string(k) + " is " + PointText(kp) +
                             ": not finite");
    }
    projected[k] = ProjectXY(frame.cam_from_hand, rig.look_at(), points[k]);
    mean_p[0] += projected[k][0] / kNumKeypoints;
    mean_p[1] += projected[k][1] / kNumKeypoints;
    mean_k[0] += kp.x / static_cast<double>(kNumKeypoints);
    mean_k[1] += kp.y / static_cast<double>(kNumKeypoints);
  }
  double cross = 0, spread = 0;
  for (int k = 0; k < kNumKeypoints; ++k) {
    const double pk[2] = {projected[k][0] - mean_p[0], projected[k][1] - mean_p[1]};
    const double kk[2] = {start.keypoints_normalised[k].x - mean_k[0],
                          start.keypoints_normalised[k].y - mean_k[1]};
    cross += pk[0] * kk[0] + pk[1] * kk[1];
    spread += pk[0] * pk[0] + pk[1] * pk[1];
  }
  frame.scale = cross / spread;
  if (!std::isfinite(frame.scale) || !(frame.scale > 0)) {
    return InvalidArgument(
        "the candidate's keypoints do not match the rig's projection of its "
        "pose (least-squares scale " +
        std::to_string(frame.scale) + ")");
  }
  frame.shift = {mean_k[0] - frame.scale * mean_p[0], mean_k[1] - frame.scale * mean_p[1]};
  double squared = 0;
  for (int k = 0; k < kNumKeypoints; ++k) {
    const double dx =
        frame.scale * projected[k][0] + frame.shift[0] - start.keypoints_normalised[k].x;
    const double dy =
        frame.scale * projected[k][1] + frame.shift[1] - start.keypoints_normalised[k].y;
    squared += dx * dx + dy * dy;
  }
  frame.alignment_rms_px = std::sqrt(squared / kNumKeypoints);
  return frame;
}

// The answer's pose-dependent fields from the parameters.
void FillPose(const HandRig& rig,
              const JointVector& joints,
              const Mat3d& cam_from_hand,
              double scale,
              const std::array<double, 2>& shift,
              PoseFit* fit) {
  fit->joints = joints;
  fit->cam_from_hand = cam_from_hand;
  fit->scale = scale;
  fit->shift = shift;
  fit->keypoints_in_hand = rig.Keypoints3d(joints);
  for (int k = 0; k < kNumKeypoints; ++k) {
    const std::array<double, 2> p =
        ProjectXY(cam_from_hand, rig.look_at(), fit->keypoints_in_hand[k]);
    fit->keypoints_normalised[k] = {static_cast<float>(scale * p[0] + shift[0]),
                                    static_cast<float>(scale * p[1] + shift[1])};
  }
  // A rotation from the solver is a rotation, so it always has a view direction and roll.
  THROW_CHECK(ViewOfCamFromHand(rig, cam_from_hand, &fit->view_direction, &fit->roll).ok());
}

double CostOf(ceres::Problem* problem,
              const std::vector<ceres::ResidualBlockId>& blocks,
              int num_threads) {
  if (blocks.empty()) return 0;
  ceres::Problem::EvaluateOptions evaluate;
  evaluate.residual_blocks = blocks;
  evaluate.num_threads = num_threads;
  double cost = 0;
  if (!problem->Evaluate(evaluate, &cost, nullptr, nullptr, nullptr)) return NAN;
  return cost;
}

}  // namespace

double SilhouetteTermCost(const HandRig& rig,
                          const SilhouetteFields& fields,
                          bool mirrored,
                          const PoseFitOptions& options,
                          const JointVector& joints,
                          const std::array<double, 4>& cam_from_hand,
                          double scale,
                          const std::array<double, 2>& shift,
                          std::vector<double>* gradient) {
  const FitKinematics kinematics(rig);
  JointVector j = joints;
  Quaternion q = cam_from_hand;
  double s = scale;
  std::array<double, 2> t = shift;
  ceres::Problem problem;
  const PoseBlocks pose{j.data(), q.data(), &s, t.data()};
  pose.AddTo(&problem);
  const std::vector<ceres::ResidualBlockId> blocks =
      AddSilhouetteBlocks(&problem,
                          kinematics,
                          rig,
                          std::make_shared<const SilhouetteFields>(fields),
                          mirrored,
                          options,
                          pose);
  ceres::Problem::EvaluateOptions evaluate;
  evaluate.residual_blocks = blocks;
  for (int d = 0; d < kNumDigits; ++d) evaluate.parameter_blocks.push_back(pose.digit(d));
  evaluate.parameter_blocks.push_back(q.data());
  evaluate.parameter_blocks.push_back(&s);
  evaluate.parameter_blocks.push_back(t.data());
  double cost = 0;
  THROW_CHECK(problem.Evaluate(evaluate, &cost, nullptr, gradient, nullptr));
  return cost;
}

double DepthTermCost(const HandRig& rig,
                     const PoseFitEvidence& evidence,
                     const PoseFitOptions& options,
                     const JointVector& joints,
                     const std::array<double, 4>& cam_from_hand,
                     std::vector<double>* gradient) {
  const FitKinematics kinematics(rig);
  JointVector j = joints;
  Quaternion q = cam_from_hand;
  ceres::Problem problem;
  double scale = 1;
  std::array<double, 2> shift{};
  const PoseBlocks pose{j.data(), q.data(), &scale, shift.data()};
  pose.AddTo(&problem);
  const std::vector<ceres::ResidualBlockId> blocks =
      AddDepthBlocks(&problem, kinematics, rig, evidence, options, j.data(), q.data());
  if (gradient != nullptr) gradient->assign(kNumJointAngles + 4, 0.0);
  if (blocks.empty()) return 0;
  ceres::Problem::EvaluateOptions evaluate;
  evaluate.residual_blocks = blocks;
  for (int d = 0; d < kNumDigits; ++d) evaluate.parameter_blocks.push_back(pose.digit(d));
  evaluate.parameter_blocks.push_back(q.data());
  double cost = 0;
  THROW_CHECK(problem.Evaluate(evaluate, &cost, nullptr, gradient, nullptr));
  return cost;
}

Result<PoseFit> FitPose(const HandRig& rig,
                        const PoseFitStart& start,
                        const PoseFitEvidence& evidence,
                        const PoseFitOptions& options) {
  if (!options.Check()) return InvalidArgument("options fail their checks (see above)");
  auto used = CheckEvidence(evidence);
  if (!used.ok()) return used.status();
  auto frame = MakeStartFrame(rig, start);
  if (!frame.ok()) return frame.status();

  // The parameter blocks, which the problem refers to by address.
  JointVector joints = frame->joints;
  Quaternion cam_from_hand = QuaternionOf(frame->cam_from_hand);
  double scale = frame->scale;
  std::array<double, 2> shift = frame->shift;
  const FitKinematics kinematics(rig);
  if (!kinematics.digit_blocks()) {
    return InvalidArgument(
        "the rig's DOFs do not turn each digit by its own 4 angles in docs/conventions.md's "
        "order");
  }

  ceres::Problem problem;  // owns the cost, loss and manifold objects given to it
  const PoseBlocks blocks{joints.data(), cam_from_hand.data(), &scale, shift.data()};
  blocks.AddTo(&problem);
  std::vector<ceres::ResidualBlockId> landmark_blocks;
  if (*used > 0) {
    for (int k = 0; k < kNumKeypoints; ++k) {
      const double w = evidence.weights[k];
      if (!(w > 0)) continue;
      // The weight scales the loss, not the residual, so a landmark becomes an outlier at the
      // same error whatever its confidence.
      ceres::LossFunction* loss = new ceres::ScaledLoss(
          new ceres::HuberLoss(options.landmark_loss_scale), w, ceres::TAKE_OWNERSHIP);
      landmark_blocks.push_back(AddLandmarkBlock(&problem,
                                                 loss,
                                                 blocks,
                                                 &kinematics,
                                                 k,
                                                 rig.look_at(),
                                                 evidence.landmarks_px[k],
                                                 1.0 / options.landmark_sigma_px));
    }
  }
  std::vector<ceres::ResidualBlockId> silhouette_blocks;
  const bool silhouette = evidence.silhouette != nullptr &&
                          options.inside_weight + options.edge_weight + options.cover_weight > 0;
  if (silhouette) {
    silhouette_blocks = AddSilhouetteBlocks(&problem,
                                            kinematics,
                                            rig,
                                            evidence.silhouette,
                                            evidence.silhouette_mirrored,
                                            options,
                                            blocks);
  }
  const std::vector<ceres::ResidualBlockId> depth_blocks = AddDepthBlocks(
      &problem, kinematics, rig, evidence, options, joints.data(), cam_from_hand.data());
  // The joints and the rotation near the candidate's.
  std::vector<ceres::ResidualBlockId> prior_blocks;
  for (int d = 0; d < kNumDigits; ++d) {
    prior_blocks.push_back(problem.AddResidualBlock(
        DigitPrior::Create(frame->joints.data() + d * kDigitDofs, options.joint_prior_sigma),
        nullptr,
        blocks.digit(d)));
  }
  prior_blocks.push_back(
      problem.AddResidualBlock(RotationPrior::Create(cam_from_hand, options.rotation_prior_sigma),
                               nullptr,
                               blocks.cam_from_hand));
  problem.SetManifold(cam_from_hand.data(), new ceres::QuaternionManifold);
  for (int i = 0; i < kNumJointAngles; ++i) {
    double* digit = blocks.digit(i / kDigitDofs);
    problem.SetParameterLowerBound(digit, i % kDigitDofs, rig.limits().min[i]);
    problem.SetParameterUpperBound(digit, i % kDigitDofs, rig.limits().max[i]);
  }
  if (*used > 0 || silhouette) {
    // The scale cannot flip the hand or collapse it; a factor 4 either way is far beyond any
    // candidate the search returns.
    problem.SetParameterLowerBound(&scale, 0, frame->scale / 4);
    problem.SetParameterUpperBound(&scale, 0, frame->scale * 4);
  }

  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = options.max_iterations;
  solver.function_tolerance = options.function_tolerance;
  solver.num_threads = options.num_threads;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);

  PoseFit fit;
  fit.start_alignment_rms_px = frame->alignment_rms_px;
  fit.initial_cost = summary.initial_cost;
  fit.final_cost = summary.final_cost;
  fit.iterations = static_cast<int>(summary.iterations.size());
  fit.termination = ceres::TerminationTypeToString(summary.termination_type);
  fit.message = summary.message;
  fit.converged = summary.termination_type == ceres::CONVERGENCE;

  bool finite = std::isfinite(scale) && std::isfinite(shift[0]) && std::isfinite(shift[1]);
  for (const double v : joints) finite = finite && std::isfinite(v);
  for (const double v : cam_from_hand) finite = finite && std::isfinite(v);
  if (!summary.IsSolutionUsable() || !finite) {
    // The answer is the start, so a caller may still use it; the flags say what happened.
    fit.converged = false;
    fit.termination = "FAILURE";
    if (!finite) fit.message = "non-finite parameters; " + summary.message;
    joints = frame->joints;
    cam_from_hand = QuaternionOf(frame->cam_from_hand);
    scale = frame->scale;
    shift = frame->shift;
  }
  fit.landmark_cost = CostOf(&problem, landmark_blocks, options.num_threads);
  fit.prior_cost = CostOf(&problem, prior_blocks, options.num_threads);
  fit.silhouette_cost = CostOf(&problem, silhouette_blocks, options.num_threads);
  fit.depth_cost = CostOf(&problem, depth_blocks, options.num_threads);
  FillPose(rig, joints, RotationOf(cam_from_hand), scale, shift, &fit);
  return fit;
}

}  // namespace handdb
