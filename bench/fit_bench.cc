// The pose fit's cost: the median time of one FitPose (pose/fit.h) on one core over synthetic
// perturbed starts, beside the time of one HandRig::Keypoints3d, the forward kinematics a fit
// evaluates (with derivatives) per landmark and iteration. Also how well the fits converge. The
// silhouette term's cost besides: the truth's capsules (pose/fit_silhouette.h) rasterised as the
// picture's hand region, its distance fields made once per picture (MakeSilhouetteFields), and
// the fit to landmarks and silhouette, and to the silhouette alone; and the fit with the depth
// term beside the landmarks. These run at PoseFitOptions' defaults (Ceres' 1e-6 stop); the
// silhouette fit `handdb query --fit on` makes of a picture without landmarks
// (MatchFitOptions::silhouette_fit: a 1e-4 stop, tighter priors, no edge part) is timed too.
//
//   fit_bench [--fits N]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "base/repo_root.h"
#include "bench/median.h"
#include "generator/sampling/random.h"
#include "pose/fit.h"
#include "pose/fit_matches.h"
#include "pose/fit_silhouette.h"

namespace handdb {
namespace {

using Clock = std::chrono::steady_clock;

using bench::Median;

// The union of the projected capsules on a 1 px grid: its outline pixels (region pixels with a
// 4-neighbour outside), which also stand for the edges.
std::vector<Point2f> CapsuleOutline(const std::vector<ProjectedCapsule>& capsules) {
  constexpr int kHalf = 170;
  constexpr int kSide = 2 * kHalf + 1;
  std::vector<uint8_t> in(kSide * kSide, 0);
  for (int y = 0; y < kSide; ++y) {
    for (int x = 0; x < kSide; ++x) {
      const double px = x - kHalf, py = y - kHalf;
      for (const ProjectedCapsule& c : capsules) {
        const double dx = c.to.x - c.from.x, dy = c.to.y - c.from.y;
        const double ex = px - c.from.x, ey = py - c.from.y;
        const double t = std::clamp((ex * dx + ey * dy) / (dx * dx + dy * dy + 1e-9), 0.0, 1.0);
        if (std::hypot(ex - t * dx, ey - t * dy) <= c.radius) {
          in[y * kSide + x] = 1;
          break;
        }
      }
    }
  }
  std::vector<Point2f> out;
  for (int y = 1; y + 1 < kSide; ++y) {
    for (int x = 1; x + 1 < kSide; ++x) {
      if (!in[y * kSide + x]) continue;
      if (!in[y * kSide + x - 1] || !in[y * kSide + x + 1] || !in[(y - 1) * kSide + x] ||
          !in[(y + 1) * kSide + x]) {
        out.push_back({static_cast<float>(x - kHalf), static_cast<float>(y - kHalf)});
      }
    }
  }
  return out;
}

NormalisedKeypoints2d Project(const HandRig& rig,
                              const JointVector& joints,
                              const Mat3d& cam_from_hand,
                              double scale) {
  const HandKeypoints3d points = rig.Keypoints3d(joints);
  NormalisedKeypoints2d out;
  for (int k = 0; k < kNumKeypoints; ++k) {
    double xy[2] = {0, 0};
    for (int r = 0; r < 2; ++r) {
      for (int c = 0; c < 3; ++c) xy[r] += cam_from_hand[r][c] * (points[k][c] - rig.look_at()[c]);
    }
    out[k] = {static_cast<float>(scale * xy[0]), static_cast<float>(scale * xy[1])};
  }
  return out;
}

int Run(int fits) {
  auto model = LoadHandModel(RepoRoot() / "configs/hands/webxr_generic_right.json");
  if (!model.ok()) {
    std::fprintf(stderr, "fit_bench: %s\n", model.status().ToString().c_str());
    return 1;
  }
  auto rig = HandRig::Create(*model);
  if (!rig.ok()) {
    std::fprintf(stderr, "fit_bench: %s\n", rig.status().ToString().c_str());
    return 1;
  }
  const JointLimits& limits = rig->limits();
  Rng rng(7);
  const PoseFitOptions options;  // one thread
  const PoseFitOptions query_silhouette = MatchFitOptions{}.silhouette_fit;
  std::vector<double> fit_ms, iterations, max_px, fields_ms, both_ms, silhouette_ms,
      silhouette_iterations, query_silhouette_ms, query_silhouette_iterations;
  const std::vector<HandCapsule> capsules = HandCapsules(*rig);
  std::vector<double> depth_ms, depth_iterations;
  const HandKeypoints3d rest = rig->Keypoints3d(JointVector{});
  const double rig_length =
      std::hypot(rest[9][0] - rest[0][0], rest[9][1] - rest[0][1], rest[9][2] - rest[0][2]);
  int converged = 0;
  for (int n = 0; n < fits; ++n) {
    // A random pose inside the limits, a random view, and a start perturbed like a near match.
    JointVector truth, start_joints;
    for (int i = 0; i < kNumJointAngles; ++i) {
      truth[i] = limits.min[i] + (limits.max[i] - limits.min[i]) * (0.1 + 0.8 * rng.Uniform());
      start_joints[i] = truth[i] + 0.4 * (rng.Uniform() - 0.5);
    }
    limits.Clamp(&start_joints);
    Vec3d direction{rng.Normal(), rng.Normal(), rng.Normal()};
    const double roll = 2 * std::acos(-1.0) * rng.Uniform();
    auto cam = CamFromHand(*rig, direction, roll);
    if (!cam.ok()) continue;
    // The start's camera: the view direction and roll moved by up to ~10 degrees.
    Vec3d start_direction = direction;
    const double length = std::sqrt(direction[0] * direction[0] + direction[1] * direction[1] +
                                    direction[2] * direction[2]);
    for (double& v : start_direction) v = v / length + 0.17 * (rng.Uniform() - 0.5);
    PoseFitStart start;
    start.joints = start_joints;
    start.view_direction = start_direction;
    start.roll = roll + 0.17 * (rng.Uniform() - 0.5);
    auto start_cam = CamFromHand(*rig, start_direction, start.roll);
    if (!start_cam.ok()) continue;
    start.keypoints_normalised = Project(*rig, start_joints, *start_cam, 1000 * 1.05);
    PoseFitEvidence evidence;
    evidence.has_landmarks = true;
    evidence.landmarks_px = Project(*rig, truth, *cam, 1000);

    const auto t0 = Clock::now();
    auto fit = FitPose(*rig, start, evidence, options);
    const auto t1 = Clock::now();
    if (!fit.ok()) {
      std::fprintf(stderr, "fit_bench: %s\n", fit.status().ToString().c_str());
      return 1;
    }
    fit_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    iterations.push_back(fit->iterations);
    converged += fit->converged ? 1 : 0;
    double worst = 0;
    for (int k = 0; k < kNumKeypoints; ++k) {
      worst =
          std::max(worst,
                   std::hypot(double{fit->keypoints_normalised[k].x} - evidence.landmarks_px[k].x,
                              double{fit->keypoints_normalised[k].y} - evidence.landmarks_px[k].y));
    }
    max_px.push_back(worst);

    // The same fit with the depth term (the truth's depths, weight 10: the weight that turns a
    // bend in pose/fit_test.cc), what PoseFitOptions::depth_weight adds to a fit.
    PoseFitEvidence with_depths = evidence;
    with_depths.has_depths = true;
    const HandKeypoints3d truth_in_hand = rig->Keypoints3d(truth);
    for (int k = 0; k < kNumKeypoints; ++k) {
      double z = 0;
      for (int c = 0; c < 3; ++c) z += (*cam)[2][c] * truth_in_hand[k][c];
      with_depths.depths[k] = static_cast<float>(z / rig_length);
    }
    PoseFitOptions depth_options = options;
    depth_options.depth_weight = 10;
    const auto d0 = Clock::now();
    auto depth_fit = FitPose(*rig, start, with_depths, depth_options);
    const auto d1 = Clock::now();
    if (!depth_fit.ok()) return 1;
    depth_ms.push_back(std::chrono::duration<double, std::milli>(d1 - d0).count());
    depth_iterations.push_back(depth_fit->iterations);

    // The same fit with the truth's silhouette as the picture's (centred on the hand).
    const HandKeypoints3d truth_points = rig->Keypoints3d(truth);
    const std::vector<Point2f> outline =
        CapsuleOutline(ProjectCapsules(capsules, truth_points, *cam, rig->look_at(), 1000, {0, 0}));
    std::vector<PointQ> edges;
    for (const Point2f& p : outline) {
      edges.push_back({static_cast<int16_t>(std::lround(p.x * kPointScale)),
                       static_cast<int16_t>(std::lround(p.y * kPointScale))});
    }
    const auto f0 = Clock::now();
    auto fields = MakeSilhouetteFields(outline, edges);
    const auto f1 = Clock::now();
    if (!fields.ok()) continue;
    fields_ms.push_back(std::chrono::duration<double, std::milli>(f1 - f0).count());
    evidence.silhouette = std::make_shared<const SilhouetteFields>(std::move(fields).value());
    const auto b0 = Clock::now();
    auto both = FitPose(*rig, start, evidence, options);
    const auto b1 = Clock::now();
    evidence.has_landmarks = false;
    auto alone = FitPose(*rig, start, evidence, options);
    const auto b2 = Clock::now();
    auto query = FitPose(*rig, start, evidence, query_silhouette);
    const auto b3 = Clock::now();
    if (!both.ok() || !alone.ok() || !query.ok()) return 1;
    both_ms.push_back(std::chrono::duration<double, std::milli>(b1 - b0).count());
    silhouette_ms.push_back(std::chrono::duration<double, std::milli>(b2 - b1).count());
    silhouette_iterations.push_back(alone->iterations);
    query_silhouette_ms.push_back(std::chrono::duration<double, std::milli>(b3 - b2).count());
    query_silhouette_iterations.push_back(query->iterations);
  }

  // The baseline: one forward kinematics evaluation in double, as the search side calls it.
  const int repeats = 20000;
  JointVector joints{};
  for (int i = 0; i < kNumJointAngles; ++i) joints[i] = 0.5 * (limits.min[i] + limits.max[i]);
  double sink = 0;
  const auto k0 = Clock::now();
  for (int n = 0; n < repeats; ++n) {
    joints[n % kNumJointAngles] += 1e-9;
    sink += rig->Keypoints3d(joints)[20][0];
  }
  const auto k1 = Clock::now();
  const double fk_us = std::chrono::duration<double, std::micro>(k1 - k0).count() / repeats;

  const double ms = Median(fit_ms);
  std::printf("fits                      %zu (converged %d)\n", fit_ms.size(), converged);
  std::printf("fit median                %.3f ms (p90 %.3f ms)\n", ms, [&] {
    std::vector<double> v = fit_ms;
    std::sort(v.begin(), v.end());
    return v[v.size() * 9 / 10];
  }());
  std::printf("iterations median         %.0f\n", Median(iterations));
  std::printf("worst keypoint median     %.3f px (normalised frame, hand diameter ~192 px)\n",
              Median(max_px));
  std::printf("fit + depth median        %.3f ms (landmarks and depths; %.0f iterations)\n",
              Median(depth_ms),
              Median(depth_iterations));
  std::printf("silhouette fields median   %.3f ms (once per picture)\n", Median(fields_ms));
  std::printf("fit + silhouette median   %.3f ms (landmarks and silhouette)\n", Median(both_ms));
  std::printf("silhouette fit median     %.3f ms (no landmarks; %.0f iterations)\n",
              Median(silhouette_ms),
              Median(silhouette_iterations));
  std::printf(
      "--fit on silhouette fit   %.3f ms (no landmarks, as handdb query fits; %.0f iterations)\n",
      Median(query_silhouette_ms),
      Median(query_silhouette_iterations));
  std::printf("HandRig::Keypoints3d      %.3f us\n", fk_us);
  std::printf("fit / Keypoints3d         %.0f x\n", ms * 1000 / fk_us);
  return sink == 12345.678 ? 2 : 0;  // keeps the baseline loop from being optimised away
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  int fits = 100;
  for (int i = 1; i + 1 < argc; ++i) {
    if (std::strcmp(argv[i], "--fits") == 0) fits = std::atoi(argv[i + 1]);
  }
  if (fits < 1) {
    std::fprintf(stderr, "usage: fit_bench [--fits N>0]\n");
    return 2;
  }
  return handdb::Run(fits);
}
