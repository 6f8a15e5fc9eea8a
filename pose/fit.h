// The pose fit: from a candidate match (a stored view: joint angles, view direction, roll), a
// bounded nonlinear least-squares fit of the hand rig to a picture's 2D evidence. The retrieval
// answers with the nearest stored view, a lookup among the database's shapes, directions and
// rolls; the fit moves the 20 joint angles (within the hand model's limits), the 3D rotation and
// the image-plane scale and shift until the rig's projected keypoints meet the picture's hand
// landmarks, while a prior holds the joints and rotation near the candidate where the evidence
// is weak (docs/decisions/0012-pose-fit-with-ceres.md).
//
// The model of the picture: the orthographic render camera of generator/hand/camera.h followed by
// the normalisation of the query (docs/conventions.md "Normalised frame"), i.e.
//   keypoint_normalised = scale * (cam_from_hand * (point_in_hand - look_at)).xy + shift
// in the query's normalised frame (px), with the roll (camera and virtual) inside cam_from_hand.
#pragma once

#include <array>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/roll.h"
#include "format/view.h"
#include "generator/hand/camera.h"
#include "generator/hand/kinematics.h"
#include "pose/fit_silhouette.h"

namespace handdb {

using NormalisedKeypoints2d = std::array<Point2f, kNumKeypoints>;

struct PoseFitOptions {
  // A landmark's residual is its error (normalised px) over this; 192 px is the hand's diameter.
  double landmark_sigma_px = 2.0;
  // Huber loss on each landmark's whitened error: beyond this many sigmas an error counts
  // linearly, so one wrong landmark does not drag the whole hand.
  double landmark_loss_scale = 3.0;
  // The prior: each joint angle (radians) and the rotation (radians, the angle between the fitted
  // and the candidate's camera) cost (change / sigma)^2 / 2.
  double joint_prior_sigma = 0.5;
  double rotation_prior_sigma = 0.35;
  // The silhouette term (pose/fit_silhouette.h), read where the evidence has the fields: points
  // on the projected capsules (along each link's axis and sides) cost their distance outside the
  // hand's region, the sides of the finger links their distance from the nearest edge, and points
  // of the silhouette's outline their distance outside the nearest capsule, each over this sigma
  // (normalised px). Each point's cost is bounded (Geman-McClure, its scale in sigmas), so a
  // side hidden behind another finger, or a patch the segmentation got wrong, pulls with at most
  // a fixed force.
  double silhouette_sigma_px = 3.0;
  double silhouette_loss_scale = 3.0;
  // Each part's total weight, in squared sigmas: all of a part's points off by e px cost
  // weight * (e / sigma)^2 / 2, however many points it has (the landmark term's 21 landmarks off
  // by e cost 21 * (e / landmark_sigma_px)^2 / 2, before their presence weight).
  double inside_weight = 10;
  double edge_weight = 10;
  double cover_weight = 10;
  // The depth term, read where the evidence has depths: per pair of keypoints (each bone, or
  // each keypoint and the wrist: `depth_from_wrist`), the fitted change in depth minus the
  // evidence's, both in the rig's wrist-to-middle-knuckle lengths, over depth_sigma, with a
  // Cauchy loss at depth_loss_scale sigmas (the network's depths are often far off; a bounded
  // pull keeps a wrong one from turning the hand), scaled by the landmark's weight times
  // depth_weight. Scale-free: the fit's own scale sets the hand's size, the picture's px never
  // meet the evidence's depths. depth_weight 0 (the default): no depth term. Off because the
  // landmark network's depths, the only source today, are worse than the fit's own: at weights
  // 0.3-10 the natural-pose photo renders' fitted error moved by less than 0.01
  // (docs/decisions/0019). Given true depths, weight 10 turns a finger bent the wrong way
  // (pose/fit_test.cc).
  double depth_sigma = 0.25;
  double depth_loss_scale = 1.0;
  double depth_weight = 0;
  bool depth_from_wrist = false;
  // Caps the work of one fit (each iteration is a few dozen microseconds).
  int max_iterations = 50;
  // Ceres' stop on the cost's relative decrease in one step (its function_tolerance).
  double function_tolerance = 1e-6;
  int num_threads = 1;
  bool Check() const;
};

// A picture's evidence in the query's normalised frame (the frame of its edge points).
struct PoseFitEvidence {
  bool has_landmarks = false;
  NormalisedKeypoints2d landmarks_px{};  // docs/conventions.md keypoint order
  // Per landmark, >= 0 (e.g. the network's presence times a per-joint confidence); 0 ignores it.
  std::array<float, kNumKeypoints> weights{};

  // The hand's silhouette and edges (MakeSilhouetteFields); null: no silhouette term. With
  // `silhouette_mirrored` the fields are read at (-x, y): a left-hand match is fitted as the
  // right hand to the mirrored picture.
  std::shared_ptr<const SilhouetteFields> silhouette;
  bool silhouette_mirrored = false;

  // Per landmark, its depth away from the camera in wrist-to-middle-knuckle lengths of the hand,
  // from any origin (only differences count): the landmark network's world joints' z over their
  // own wrist-to-middle-knuckle distance. Weighted by `weights`; used with has_landmarks.
  bool has_depths = false;
  std::array<float, kNumKeypoints> depths{};

  PoseFitEvidence() { weights.fill(1.0f); }
};

// Where a fit starts: a candidate match's pose and its stored keypoints.
struct PoseFitStart {
  JointVector joints{};  // clamped into the rig's limits before the fit
  Vec3d view_direction{};
  double roll = 0;  // the view's camera roll plus its virtual roll (radians)
  // The candidate's 21 keypoints in the normalised frame (what ViewKeypointsNormalised gives):
  // the start's scale and shift are the least-squares fit of the rig's projection onto them.
  NormalisedKeypoints2d keypoints_normalised{};
};

// The start of a stored view (v, r): its label's pose with the virtual roll added, and its
// keypoints recomputed by the rig in the normalised frame.
Result<PoseFitStart> PoseFitStartFromLabel(const HandRig& rig,
                                           const ViewLabel& label,
                                           const RenderSettings& render,
                                           double virtual_roll);

struct PoseFit {
  JointVector joints{};
  Mat3d cam_from_hand{};  // rows: the camera's x, y, z axes in the hand frame
  Vec3d view_direction{};
  double roll = 0;   // of cam_from_hand, as CamFromHand(rig, view_direction, roll) defines it
  double scale = 0;  // normalised px per hand-frame unit
  std::array<double, 2> shift{};  // normalised px
  HandKeypoints3d keypoints_in_hand{};
  NormalisedKeypoints2d keypoints_normalised{};

  // RMS distance (px) of the start's projection from the candidate's own keypoints after the
  // scale and shift fit: ~0 when the candidate's label and the rig agree.
  double start_alignment_rms_px = 0;
  // Ceres' costs (1/2 sum of the loss of the squared residuals): of the whole problem before and
  // after, and the final cost per residual kind.
  double initial_cost = 0;
  double final_cost = 0;
  double landmark_cost = 0;
  double prior_cost = 0;
  double silhouette_cost = 0;  // 0 without the silhouette term
  double depth_cost = 0;       // 0 without the depth term
  int iterations = 0;
  std::string termination;  // Ceres' termination type: CONVERGENCE, NO_CONVERGENCE, FAILURE, ...
  std::string message;      // Ceres' own words about why it stopped
  // The solver met a tolerance. False on hitting max_iterations (the answer is still the best
  // iterate) and on a failure (the answer is then the start).
  bool converged = false;
};

// Fits the rig to the evidence from `start`. kInvalidArgument for options that fail Check(),
// non-finite or negative evidence, or a start whose pose or keypoints are unusable; a solver that
// fails or does not converge is reported in the answer, never thrown. Without landmarks (or with
// every weight 0) and without a silhouette nothing pulls away from the start and the answer is
// the start.
Result<PoseFit> FitPose(const HandRig& rig,
                        const PoseFitStart& start,
                        const PoseFitEvidence& evidence,
                        const PoseFitOptions& options);

// The silhouette term's cost (1/2 the sum of its squared residuals) at a pose, and with `gradient`
// its gradient over the fit's parameters in the solver's order: the 20 joint angles, the rotation
// as a unit quaternion (w, x, y, z, of cam_from_hand), the scale, the shift (x, y). What the
// solver differentiates, open to tests and studies.
double SilhouetteTermCost(const HandRig& rig,
                          const SilhouetteFields& fields,
                          bool mirrored,
                          const PoseFitOptions& options,
                          const JointVector& joints,
                          const std::array<double, 4>& cam_from_hand,
                          double scale,
                          const std::array<double, 2>& shift,
                          std::vector<double>* gradient = nullptr);

// The depth term's cost at a pose (the evidence's depths and weights, the options' depth
// settings), and with `gradient` its gradient over the 20 joint angles and the rotation (w, x, y,
// z), the only parameters it reads. What the solver differentiates, open to tests.
double DepthTermCost(const HandRig& rig,
                     const PoseFitEvidence& evidence,
                     const PoseFitOptions& options,
                     const JointVector& joints,
                     const std::array<double, 4>& cam_from_hand,
                     std::vector<double>* gradient = nullptr);

// The view direction and roll of a camera rotation, the inverse of CamFromHand.
Status ViewOfCamFromHand(const HandRig& rig,
                         const Mat3d& cam_from_hand,
                         Vec3d* view_direction,
                         double* roll);

// FitPose's and SilhouetteTermCost's solver, Ceres, is in a shared object of its own
// (libhanddb_fit.so, pose/fit_plugin.h), so a process that fits nothing never loads it: it is
// opened on the first of those calls. LoadPoseFitSolver opens it now, so a command can load it
// beside other work and report a missing plugin before it starts; once per process, later calls
// return the first answer. kNotFound names the places looked in; a plugin that is not this
// build's is refused (kUnsupportedVersion). Without it FitPose returns that status and
// SilhouetteTermCost throws it.
Status LoadPoseFitSolver();

// Where the plugin is looked for: $HANDDB_FIT_PLUGIN alone when set; else, in order, beside the
// running executable, in its ../lib/handdb, beside the shared object holding this code (the
// Python module), then the build tree's.
std::vector<std::filesystem::path> PoseFitSolverCandidates();

}  // namespace handdb
