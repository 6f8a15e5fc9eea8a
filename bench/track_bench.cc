// Video tracking (docs/track.md) on sequences made from a database's own views, in one run:
// frames/s with a full search every frame against the local search, medians and their ratio,
// and what the local search and the smoothing cost or gain in accuracy:
//   (a) a view sequence: 256 px edge-image frames of a hand that turns in the picture
//       (`--turn` rad a frame), moves to a neighbouring view direction every `--dir-every`
//       frames and to another shape every `--shape-every` frames, each frame's view drawn from
//       the database's points with a random 15% dropped and the rest moved by up to 0.5 px;
//       every `--leave-every` frames the hand leaves for 5 blank frames and comes back in another
//       pose. The truth is the view's keypoints moved like its points. Per mode: frames/s, the
//       keypoint error (mean px of the 21 keypoints in the frame), the jitter (mean px of each
//       keypoint's frame-to-frame motion less the truth's), and after each return, how often the
//       hand is found again (error below 10% of the hand's size) within 5 frames;
//   (b) a photo sequence (with --photo): one photo turned 1 degree a frame about its centre,
//       frames/s and the jitter against that turn, through the photo path with the landmarks.
// The modes: full search every frame without smoothing (each frame answered alone), local
// search without smoothing, local + online smoothing, local + offline smoothing.
//
//   track_bench --db DIR [--frames 300] [--photo PNG] [--threads 2] [--repeats 3]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>
#include <vector>

#include "bench/bench_args.h"
#include "bench/median.h"
#include "photo/hand_landmarks.h"
#include "query/searcher.h"
#include "track/frames.h"
#include "track/tracker.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using bench::Median;

struct Args {
  std::string db;
  std::string photo;
  std::string work = (fs::temp_directory_path() / "handdb-track-bench").string();
  int frames = 300;
  int threads = 2;
  int repeats = 3;
  double turn = 0.02;
  int dir_every = 20;
  int shape_every = 60;
  int leave_every = 100;
  uint32_t seed = 1;
  double drop = 0.15;  // share of each frame's points dropped
  // Swept (comma lists): the local search's neighbourhood.
  std::vector<double> directions = {30};
  std::vector<int> rolls = {2};
  std::vector<double> joints = {-1};
  int full_every = TrackOptions{}.full_every;
  double min_cutoff_hz = KeypointFilterOptions{}.min_cutoff_hz;
  double beta = KeypointFilterOptions{}.beta;
  double joint_cost = TransitionCosts{}.joint;
};

struct Truth {
  bool hand = false;
  view_id_t view = kInvalidViewId;  // the stored view drawn: the truth jumps when it changes
  std::array<Point2f, kNumKeypoints> keypoints{};
  double size_px = 0;  // the hand's diameter in the frame
};

constexpr int kSide = 256;
constexpr double kScale = 0.85 * kSide / kNormalisedDiameter;  // frame px per normalised px

// The view sequence's frames as PNGs in `dir`, and their truth.
std::vector<Truth> MakeViewSequence(const Database& db, const Args& args, const fs::path& dir) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::mt19937 rng(args.seed);
  // Views by (shape, direction): the sequence walks the directions of one shape.
  std::map<std::pair<uint32_t, uint32_t>, view_id_t> by_shape_dir;
  std::map<uint32_t, std::vector<uint32_t>> dirs_of_shape;
  for (view_id_t v = 0; v < db.num_views(); ++v) {
    const ViewLabel l = db.label(v);
    by_shape_dir[{l.shape_id, l.dir_id}] = v;
    dirs_of_shape[l.shape_id].push_back(l.dir_id);
  }
  std::vector<uint32_t> shapes;
  for (const auto& [s, d] : dirs_of_shape) shapes.push_back(s);
  auto pick = [&](const std::vector<uint32_t>& v) {
    return v[std::uniform_int_distribution<size_t>(0, v.size() - 1)(rng)];
  };
  uint32_t shape = pick(shapes);
  view_id_t view = by_shape_dir[{shape, pick(dirs_of_shape[shape])}];
  std::uniform_real_distribution<double> u(-1, 1);
  double angle = M_PI * u(rng);
  std::vector<Truth> truth;
  int away = 0;
  for (int t = 0; t < args.frames; ++t) {
    Truth tr;
    char name[32];
    std::snprintf(name, sizeof(name), "f%05d.png", t);
    cv::Mat frame = cv::Mat::zeros(kSide, kSide, CV_8U);
    if (t > 0 && t % args.leave_every == 0) away = 5;
    if (away > 0) {
      --away;
      if (away == 0) {  // back in another pose
        shape = pick(shapes);
        view = by_shape_dir[{shape, pick(dirs_of_shape[shape])}];
        angle = M_PI * u(rng);
      }
      cv::imwrite((dir / name).string(), frame);
      truth.push_back(tr);
      continue;
    }
    if (t > 0 && t % args.shape_every == 0) {
      shape = pick(shapes);
      const uint32_t d = db.label(view).dir_id;
      if (by_shape_dir.count({shape, d})) view = by_shape_dir[{shape, d}];
    } else if (t > 0 && t % args.dir_every == 0) {
      // The nearest other direction of the shape, one of the three nearest at random.
      const ViewLabel l = db.label(view);
      std::vector<std::pair<double, view_id_t>> near;
      for (uint32_t d : dirs_of_shape[l.shape_id]) {
        if (d == l.dir_id) continue;
        const view_id_t w = by_shape_dir[{l.shape_id, d}];
        const ViewLabel m = db.label(w);
        double dot = 0;
        for (int i = 0; i < 3; ++i) dot += double(l.view_direction[i]) * m.view_direction[i];
        near.push_back({-dot, w});
      }
      std::sort(near.begin(), near.end());
      if (!near.empty()) {
        view = near[std::uniform_int_distribution<size_t>(
                        0, std::min<size_t>(3, near.size()) - 1)(rng)]
                   .second;
      }
    }
    angle += args.turn;
    const double c = std::cos(angle), s = std::sin(angle);
    const double cx = kSide / 2.0 + 6 * std::sin(t * 0.05),
                 cy = kSide / 2.0 + 4 * std::cos(t * 0.07);
    auto to_frame = [&](double x, double y) {
      return Point2f{static_cast<float>(cx + kScale * (c * x - s * y)),
                     static_cast<float>(cy + kScale * (s * x + c * y))};
    };
    std::uniform_real_distribution<double> keep(0, 1), wiggle(-0.5, 0.5);
    for (const PointQ& q : db.points(view)) {
      if (keep(rng) < args.drop) continue;
      const Point2f p = to_frame(PointQToPx(q.x), PointQToPx(q.y));
      const int x = static_cast<int>(std::floor(p.x + wiggle(rng)));
      const int y = static_cast<int>(std::floor(p.y + wiggle(rng)));
      if (x >= 0 && y >= 0 && x < kSide && y < kSide) frame.at<uint8_t>(y, x) = 255;
    }
    cv::imwrite((dir / name).string(), frame);
    tr.hand = true;
    tr.view = view;
    const ViewLabel l = db.label(view);
    for (int k = 0; k < kNumKeypoints; ++k) {
      // Pixel centres at integer + 0.5 (QueryEdges::ImageFromNormalised).
      const Point2f p = to_frame(l.keypoints[k][0], l.keypoints[k][1]);
      tr.keypoints[k] = {p.x + 0.5f, p.y + 0.5f};
    }
    tr.size_px = kScale * kNormalisedDiameter;
    truth.push_back(tr);
  }
  return truth;
}

struct Mode {
  std::string name;
  bool local = true;
  Smoothing smoothing = Smoothing::kOff;
};

struct Run {
  double fps = 0;
  std::vector<TrackFrame> frames;
};

Run TrackOnce(const Searcher& searcher, const fs::path& dir, const TrackOptions& options) {
  auto source = OpenFrameFolder(dir);
  if (!source.ok()) {
    std::fprintf(stderr, "%s\n", source.status().ToString().c_str());
    std::exit(1);
  }
  Run run;
  const auto start = std::chrono::steady_clock::now();
  auto summary = TrackFrames(searcher, **source, options, [&](const TrackFrame& f) {
    TrackFrame kept = f;
    kept.evidence.reset();  // the bench keeps the answers only
    run.frames.push_back(std::move(kept));
    return Status::Ok();
  });
  if (!summary.ok()) {
    std::fprintf(stderr, "%s\n", summary.status().ToString().c_str());
    std::exit(1);
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  run.fps = static_cast<double>(run.frames.size()) / s;
  return run;
}

double KeypointError(const TrackFrame& f, const Truth& t) {
  double e = 0;
  for (int k = 0; k < kNumKeypoints; ++k) {
    e += std::hypot(f.keypoints_image_px[k].x - t.keypoints[k].x,
                    f.keypoints_image_px[k].y - t.keypoints[k].y);
  }
  return e / kNumKeypoints;
}

struct Scores {
  double error = 0, jitter = 0, shake = 0, refound = 0;
  int returns = 0, local = 0, full = 0;
};

Scores Score(const std::vector<TrackFrame>& frames, const std::vector<Truth>& truth) {
  Scores s;
  std::vector<double> errors, jitters, shakes;
  for (size_t t = 0; t < frames.size(); ++t) {
    const TrackFrame& f = frames[t];
    s.local += f.found == FoundBy::kLocal;
    s.full += f.found == FoundBy::kFull;
    if (!truth[t].hand) continue;
    if (f.has_pose) errors.push_back(KeypointError(f, truth[t]));
    // Jitter and shake over frames of one stored view only: where the drawn view changes (a new
    // direction or shape) the truth itself jumps, which no smoothing should follow.
    if (t > 0 && f.has_pose && frames[t - 1].has_pose && truth[t - 1].hand &&
        truth[t - 1].view == truth[t].view) {
      double j = 0;
      for (int k = 0; k < kNumKeypoints; ++k) {
        const double dx = (f.keypoints_image_px[k].x - frames[t - 1].keypoints_image_px[k].x) -
                          (truth[t].keypoints[k].x - truth[t - 1].keypoints[k].x);
        const double dy = (f.keypoints_image_px[k].y - frames[t - 1].keypoints_image_px[k].y) -
                          (truth[t].keypoints[k].y - truth[t - 1].keypoints[k].y);
        j += std::hypot(dx, dy);
      }
      jitters.push_back(j / kNumKeypoints);
    }
    // Shake: the second difference of the error (answer less truth) over three frames, which a
    // steady lag does not have and a flip back and forth has twice.
    if (t > 1 && f.has_pose && frames[t - 1].has_pose && frames[t - 2].has_pose &&
        truth[t - 1].hand && truth[t - 2].hand && truth[t - 1].view == truth[t].view &&
        truth[t - 2].view == truth[t].view) {
      double a = 0;
      for (int k = 0; k < kNumKeypoints; ++k) {
        auto err = [&](size_t i, bool x) {
          return x ? frames[i].keypoints_image_px[k].x - truth[i].keypoints[k].x
                   : frames[i].keypoints_image_px[k].y - truth[i].keypoints[k].y;
        };
        a += std::hypot(err(t, true) - 2 * err(t - 1, true) + err(t - 2, true),
                        err(t, false) - 2 * err(t - 1, false) + err(t - 2, false));
      }
      shakes.push_back(a / kNumKeypoints);
    }
  }
  // Returns: the first frame with a hand after frames without one.
  int found_again = 0;
  for (size_t t = 1; t < frames.size(); ++t) {
    if (!truth[t].hand || truth[t - 1].hand) continue;
    ++s.returns;
    for (size_t d = 0; d < 5 && t + d < frames.size() && truth[t + d].hand; ++d) {
      const TrackFrame& f = frames[t + d];
      if (f.has_pose && KeypointError(f, truth[t + d]) < 0.1 * truth[t + d].size_px) {
        ++found_again;
        break;
      }
    }
  }
  double sum = 0;
  for (double e : errors) sum += e;
  s.error = errors.empty() ? 0 : sum / errors.size();
  sum = 0;
  for (double j : jitters) sum += j;
  s.jitter = jitters.empty() ? 0 : sum / jitters.size();
  sum = 0;
  for (double a : shakes) sum += a;
  s.shake = shakes.empty() ? 0 : sum / shakes.size();
  s.refound = s.returns ? double(found_again) / s.returns : 1;
  return s;
}

// The photo sequence: one photo turned 1 degree a frame about its centre.
void MakePhotoSequence(const fs::path& photo, int n, const fs::path& dir) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  const cv::Mat img = cv::imread(photo.string(), cv::IMREAD_COLOR);
  if (img.empty()) {
    std::fprintf(stderr, "%s: cannot read\n", photo.c_str());
    std::exit(1);
  }
  for (int t = 0; t < n; ++t) {
    const cv::Mat m =
        cv::getRotationMatrix2D(cv::Point2f(img.cols / 2.0f, img.rows / 2.0f), t, 1.0);
    cv::Mat out;
    cv::warpAffine(img, out, m, img.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    char name[32];
    std::snprintf(name, sizeof(name), "p%05d.png", t);
    cv::imwrite((dir / name).string(), out);
  }
}

// Jitter against the known turn: each keypoint's motion less where the turn moved it.
double PhotoJitter(const std::vector<TrackFrame>& frames, cv::Size size) {
  const double a = -M_PI / 180;  // getRotationMatrix2D's positive angle turns anticlockwise
  const double c = std::cos(a), s = std::sin(a);
  const double cx = size.width / 2.0, cy = size.height / 2.0;
  std::vector<double> j;
  for (size_t t = 1; t < frames.size(); ++t) {
    if (!frames[t].has_pose || !frames[t - 1].has_pose) continue;
    double sum = 0;
    for (int k = 0; k < kNumKeypoints; ++k) {
      const Point2f p = frames[t - 1].keypoints_image_px[k];
      const double x = cx + c * (p.x - cx) - s * (p.y - cy);
      const double y = cy + s * (p.x - cx) + c * (p.y - cy);
      sum +=
          std::hypot(frames[t].keypoints_image_px[k].x - x, frames[t].keypoints_image_px[k].y - y);
    }
    j.push_back(sum / kNumKeypoints);
  }
  double total = 0;
  for (double v : j) total += v;
  return j.empty() ? 0 : total / j.size();
}

int Main(int argc, char** argv) {
  Args args;
  CLI::App app{"handdb track: frames/s full vs local search, accuracy and jitter", "track_bench"};
  app.add_option("--db", args.db, "database directory")->required();
  app.add_option("--photo", args.photo, "a photo for the photo sequence (b)");
  app.add_option("--work", args.work, "where the frames are written")->capture_default_str();
  app.add_option("--frames", args.frames, "frames of the view sequence")->capture_default_str();
  app.add_option("--threads", args.threads, "search threads")->capture_default_str();
  app.add_option("--repeats", args.repeats, "runs per mode (frames/s: their median)")
      ->capture_default_str();
  app.add_option("--turn", args.turn, "rad a frame")->capture_default_str();
  app.add_option("--leave-every", args.leave_every, "frames between the hand's absences")
      ->capture_default_str();
  app.add_option("--seed", args.seed, "the sequence's random seed")->capture_default_str();
  app.add_option("--drop", args.drop, "share of each frame's points dropped")
      ->capture_default_str();
  bench::AddList(app, "--directions", args.directions, "local search: degrees (swept)");
  bench::AddList(app, "--rolls", args.rolls, "local search: roll steps (swept)");
  bench::AddList(app, "--joints", args.joints, "local search: joint radius, -1 all (swept)");
  app.add_option("--full-every", args.full_every, "a full search every N frames")
      ->capture_default_str();
  app.add_option("--min-cutoff", args.min_cutoff_hz, "keypoint filter: Hz")->capture_default_str();
  app.add_option("--beta", args.beta, "keypoint filter: per px/s")->capture_default_str();
  app.add_option("--joint-cost", args.joint_cost, "transition cost per radian of joint angles")
      ->capture_default_str();
  if (int rc = bench::ParseBenchArgs(app, argc, argv); rc >= 0) return rc;

  SearcherOptions open;
  open.num_threads = args.threads;
  open.use_index = IndexUse::kExact;
  auto searcher = Searcher::Open(args.db, open);
  if (!searcher.ok()) {
    std::fprintf(stderr, "%s\n", searcher.status().ToString().c_str());
    return 1;
  }
  (*searcher)->PrepareExactSearch();
  const fs::path views_dir = fs::path(args.work) / "views";
  const std::vector<Truth> truth = MakeViewSequence((*searcher)->database(), args, views_dir);
  std::printf("view sequence: %d frames of %d px, %s, threads %d\n",
              args.frames,
              kSide,
              args.db.c_str(),
              args.threads);

  TrackOptions base;
  base.picture.search.top_k = 10;
  base.picture.search.hand = Hand::kEither;
  base.picture.search.num_threads = args.threads;
  base.full_every = args.full_every;
  base.keypoint_filter.min_cutoff_hz = args.min_cutoff_hz;
  base.keypoint_filter.beta = args.beta;
  base.transition.joint = args.joint_cost;
  const std::vector<Mode> modes = {{"full, alone", false, Smoothing::kOff},
                                   {"local", true, Smoothing::kOff},
                                   {"local+online", true, Smoothing::kOnline},
                                   {"local+offline", true, Smoothing::kOffline},
                                   {"full+online", false, Smoothing::kOnline}};
  std::printf("%-44s %8s %7s %7s %7s %7s %7s %6s %6s\n",
              "mode",
              "frames/s",
              "err px",
              "jitter",
              "shake",
              "refound",
              "returns",
              "local",
              "full");
  double full_fps = 0;
  for (double directions : args.directions) {
    for (int rolls : args.rolls) {
      for (double joints : args.joints) {
        for (const Mode& mode : modes) {
          if (!mode.local && (directions != args.directions.front() ||
                              rolls != args.rolls.front() || joints != args.joints.front())) {
            continue;
          }
          TrackOptions o = base;
          o.local_search = mode.local;
          o.smoothing = mode.smoothing;
          o.local.direction_deg = directions;
          o.local.roll_steps = rolls;
          o.local.joint_radius = joints;
          std::vector<double> fps;
          Run run;
          for (int r = 0; r < args.repeats; ++r) {
            run = TrackOnce(**searcher, views_dir, o);
            fps.push_back(run.fps);
          }
          const Scores s = Score(run.frames, truth);
          char name[96];
          std::snprintf(name,
                        sizeof(name),
                        "%s (%g deg, %d rolls, %s)",
                        mode.name.c_str(),
                        directions,
                        rolls,
                        joints < 0 ? "all shapes" : ("joints " + std::to_string(joints)).c_str());
          const double f = Median(fps);
          if (!mode.local && mode.smoothing == Smoothing::kOff) full_fps = f;
          std::printf("%-44s %8.1f %7.2f %7.2f %7.2f %7.2f %7d %6d %6d   x%.1f\n",
                      mode.local ? name : mode.name.c_str(),
                      f,
                      s.error,
                      s.jitter,
                      s.shake,
                      s.refound,
                      s.returns,
                      s.local,
                      s.full,
                      full_fps > 0 ? f / full_fps : 0.0);
          std::fflush(stdout);
        }
      }
    }
  }

  if (!args.photo.empty()) {
    const int n = 90;
    const fs::path photo_dir = fs::path(args.work) / "photo";
    MakePhotoSequence(args.photo, n, photo_dir);
    TrackOptions o = base;
    auto model = HandLandmarker::Open(HandLandmarker::DefaultModelPath());
    if (model.ok()) o.picture.picture.landmarker = *model;
    const cv::Size size = cv::imread(args.photo).size();
    std::printf("\nphoto sequence: %s turned 1 degree a frame, %d frames, landmarks %s\n",
                args.photo.c_str(),
                n,
                model.ok() ? "on" : "off");
    double full = 0;
    for (const Mode& mode : modes) {
      TrackOptions m = o;
      m.local_search = mode.local;
      m.smoothing = mode.smoothing;
      std::vector<double> fps;
      Run run;
      for (int r = 0; r < args.repeats; ++r) {
        run = TrackOnce(**searcher, photo_dir, m);
        fps.push_back(run.fps);
      }
      int with_pose = 0;
      for (const TrackFrame& f : run.frames) with_pose += f.has_pose;
      const double f = Median(fps);
      if (!mode.local && mode.smoothing == Smoothing::kOff) full = f;
      std::printf("%-16s %8.1f frames/s  jitter %6.2f px  with a pose %d/%d   x%.1f\n",
                  mode.name.c_str(),
                  f,
                  PhotoJitter(run.frames, size),
                  with_pose,
                  n,
                  full > 0 ? f / full : 0.0);
      std::fflush(stdout);
    }
  }
  return 0;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) { return handdb::Main(argc, argv); }
