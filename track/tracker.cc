#include "track/tracker.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <deque>
#include <limits>
#include <utility>

#include "base/progress.h"
#include "photo/hand_landmarks.h"
#include "pose/landmark_rank.h"

namespace handdb {
namespace {

bool SamePoints(const std::vector<PointQ>& a, const std::vector<PointQ>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(PointQ)) == 0);
}

double BestDistance(const std::vector<Match>& matches) {
  double best = std::numeric_limits<double>::infinity();
  for (const Match& m : matches) best = std::min(best, m.distance);
  return best;
}

class Tracker {
 public:
  Tracker(const Searcher& searcher, const TrackOptions& options)
      : searcher_(searcher),
        options_(options),
        filter_(options.keypoint_filter),
        filter_3d_(options.keypoint_filter) {
    if (options_.local_search) {
      neighbourhood_ = std::make_unique<ViewNeighbourhood>(searcher.database());
    }
  }

  // The frame's evidence and matches, found by the full or the local search or carried.
  TrackFrame Answer(const Frame& frame) {
    const auto start = std::chrono::steady_clock::now();
    TrackFrame out;
    out.index = frame.index;
    out.time_s = frame.time_s;
    out.source = frame.name;
    out.error = frame.error;
    if (options_.keep_pixels && frame.has_pixels && frame.pixels.channels == 3) {
      const PicturePixels& p = frame.pixels;
      const size_t row = static_cast<size_t>(p.width) * 3;
      out.frame_bgr.resize(row * p.height);
      for (int y = 0; y < p.height; ++y) {
        std::memcpy(
            out.frame_bgr.data() + row * y, p.data + (p.row_bytes ? p.row_bytes : row) * y, row);
      }
      out.frame_width = p.width;
      out.frame_height = p.height;
    }
    if (out.error.ok()) {
      PictureOptions picture = options_.picture.picture;
      picture.landmark_start = next_landmark_crop_;
      next_landmark_crop_.reset();
      Result<PictureEvidence> evidence = frame.has_pixels
                                             ? ReadPicturePixels(frame.name, frame.pixels, picture)
                                             : ReadPicture(frame.path, picture);
      if (evidence.ok()) {
        if (options_.landmark_tracking && evidence->landmarks &&
            evidence->landmarks->presence >= kTrackedCropPresence) {
          next_landmark_crop_ = CropAroundLandmarks(*evidence->landmarks);
        }
        out.evidence = std::move(evidence).value();
      } else {
        out.error = evidence.status();
      }
    }
    if (out.error.ok()) Search(&out);
    const StatusCode code = out.error.code();
    if (code == StatusCode::kNotFound || code == StatusCode::kBadImage ||
        code == StatusCode::kIoError) {
      // A missing or undecodable frame says nothing of the hand: the next frame starts from the
      // last answer.
      out.found = FoundBy::kNone;
    } else if (!out.error.ok() || out.matches.empty()) {
      // No hand, or none found: lost, and the next frame with one is searched in full.
      out.found = FoundBy::kNone;
      if (out.error.ok()) out.error = Status(StatusCode::kNotFound, frame.name + ": no match");
      previous_.reset();
      previous_points_.clear();
      recent_best_.clear();
    } else {
      previous_points_ = out.evidence->edges.points;
    }
    out.seconds = SecondsSince(start);
    return out;
  }

  // The online choice for `frame` (the newest): the last of the window's best path.
  int ChooseOnline(const TrackFrame& frame) {
    if (frame.matches.empty()) {
      window_.clear();
      return -1;
    }
    window_.push_back(CandidatesOf(frame.matches));
    while (static_cast<int>(window_.size()) > options_.window) window_.pop_front();
    const std::vector<std::vector<PoseCandidate>> frames(window_.begin(), window_.end());
    return ChooseByDynamicProgramming(frames, options_.transition).back();
  }

  // Sets the chosen match as the next frame's start.
  void Chose(const TrackFrame& frame) {
    if (frame.chosen >= 0) previous_ = frame.matches[frame.chosen];
  }

  // The chosen match fitted (with a rig) and its keypoints in the frame's px, unfiltered.
  void Pose(TrackFrame* frame) const {
    frame->has_pose = false;
    if (frame->chosen < 0 || !frame->evidence) return;
    const auto start = std::chrono::steady_clock::now();
    const Match& m = frame->matches[frame->chosen];
    const QueryEdges& edges = frame->evidence->edges;
    for (int k = 0; k < kNumKeypoints; ++k) {
      frame->keypoints_image_px[k] =
          edges.ImageFromNormalised({m.label.keypoints[k][0], m.label.keypoints[k][1]});
      for (int c = 0; c < 3; ++c) frame->keypoints_3d[k][c] = m.label.keypoints[k][c];
    }
    if (options_.picture.rig != nullptr) {
      auto fit = FitPictureMatches(
          *options_.picture.rig, searcher_.database(), *frame->evidence, {m}, options_.picture.fit);
      if (fit.ok()) {
        frame->fit = std::move(fit).value();
        if (frame->fit.best == 0) {
          const MatchFit& fitted = frame->fit.fits[0];
          frame->keypoints_image_px = fitted.keypoints_image_px;
          for (int k = 0; k < kNumKeypoints; ++k) {
            for (int c = 0; c < 3; ++c) {
              frame->keypoints_3d[k][c] = static_cast<float>(fitted.keypoints_3d[k][c]);
            }
          }
        }
      }
    }
    frame->has_pose = true;
    frame->seconds += SecondsSince(start);
  }

  // Online keypoint filter, restarted after a frame without a pose.
  void FilterOnline(TrackFrame* frame) {
    if (!frame->has_pose) {
      filter_.Reset();
      filter_3d_.Reset();
      return;
    }
    if (options_.keypoint_filter.enabled && options_.smoothing != Smoothing::kOff) {
      frame->keypoints_image_px = filter_.Filter(frame->keypoints_image_px, frame->time_s);
      frame->keypoints_3d = filter_3d_.Filter(frame->keypoints_3d, frame->time_s);
    }
  }

 private:
  void Search(TrackFrame* out) {
    const PictureEvidence& evidence = *out->evidence;
    if (previous_ && SamePoints(evidence.edges.points, previous_points_) &&
        !previous_matches_.empty()) {
      out->matches = previous_matches_;
      out->landmarks_used = previous_landmarks_used_;
      out->found = FoundBy::kCarried;
      return;
    }
    out->landmarks_used = UsesLandmarks(evidence, options_.picture.landmark_rank);
    const bool due = options_.full_every > 0 && out->index - last_full_ >= options_.full_every;
    if (options_.local_search && previous_ && !due) {
      const std::vector<SearchPair> subset = neighbourhood_->Near(*previous_, options_.local);
      SearchOptions local = options_.picture.search;
      local.subset = subset;
      // The neighbourhood holds the previous hand's pairs only: searching that hand alone spares
      // the other hand's slots and their grids.
      if (local.hand == Hand::kEither) local.hand = previous_->hand;
      SearchStats stats;
      auto matches =
          SearchEvidence(searcher_, evidence, local, options_.picture.landmark_rank, &stats);
      out->pairs_searched += stats.bounded;
      out->search_seconds += stats.seconds_total;
      if (!matches.ok()) {
        out->error = matches.status();
        return;
      }
      if (!matches->empty() && BestDistance(*matches) <= options_.refind_ratio * Reference() +
                                                             options_.refind_margin_px) {
        out->matches = std::move(matches).value();
        out->found = FoundBy::kLocal;
        Keep(*out);
        return;
      }
    }
    SearchStats stats;
    auto matches = SearchEvidence(
        searcher_, evidence, options_.picture.search, options_.picture.landmark_rank, &stats);
    out->pairs_searched += stats.bounded;
    out->search_seconds += stats.seconds_total;
    if (!matches.ok()) {
      out->error = matches.status();
      return;
    }
    out->matches = std::move(matches).value();
    out->found = FoundBy::kFull;
    last_full_ = out->index;
    Keep(*out);
  }

  void Keep(const TrackFrame& frame) {
    recent_best_.push_back(BestDistance(frame.matches));
    if (recent_best_.size() > kReferenceFrames) recent_best_.pop_front();
    previous_matches_ = frame.matches;
    previous_landmarks_used_ = frame.landmarks_used;
    if (!frame.matches.empty()) previous_ = frame.matches.front();
  }

  const Searcher& searcher_;
  const TrackOptions& options_;
  std::unique_ptr<ViewNeighbourhood> neighbourhood_;
  std::optional<Match> previous_;  // the last frame's answer: the local search's centre
  std::vector<PointQ> previous_points_;
  std::vector<Match> previous_matches_;
  bool previous_landmarks_used_ = false;
  std::optional<LandmarkCrop> next_landmark_crop_;
  int64_t last_full_ = std::numeric_limits<int64_t>::min() / 2;
  // The best D_c of the last frames answered: the local search's yardstick.
  static constexpr size_t kReferenceFrames = 4;
  std::deque<double> recent_best_;
  double Reference() const {
    return recent_best_.empty() ? 0.0 : *std::max_element(recent_best_.begin(), recent_best_.end());
  }
  std::deque<std::vector<PoseCandidate>> window_;
  KeypointFilter<Keypoints2d> filter_;
  KeypointFilter<Keypoints3d> filter_3d_;
};

}  // namespace

std::string_view SmoothingName(Smoothing s) {
  switch (s) {
    case Smoothing::kOff:
      return "off";
    case Smoothing::kOnline:
      return "online";
    case Smoothing::kOffline:
      return "offline";
  }
  return "?";
}

Result<Smoothing> ParseSmoothing(std::string_view name) {
  for (Smoothing s : {Smoothing::kOff, Smoothing::kOnline, Smoothing::kOffline}) {
    if (name == SmoothingName(s)) return s;
  }
  return Status(StatusCode::kInvalidArgument,
                "unknown smoothing '" + std::string(name) + "' (off, online or offline)");
}

std::string_view FoundByName(FoundBy f) {
  switch (f) {
    case FoundBy::kNone:
      return "none";
    case FoundBy::kFull:
      return "full";
    case FoundBy::kLocal:
      return "local";
    case FoundBy::kCarried:
      return "carried";
  }
  return "?";
}

bool TrackOptions::Check() const {
  CHECK_OPTION(picture.Check());
  CHECK_OPTION(local.Check());
  CHECK_OPTION_GE(full_every, 0);
  CHECK_OPTION(refind_ratio >= 1);
  CHECK_OPTION(refind_margin_px >= 0);
  CHECK_OPTION_GE(window, 1);
  CHECK_OPTION(transition.Check());
  CHECK_OPTION(keypoint_filter.Check());
  CHECK_OPTION(picture.search.subset.empty());
  return true;
}

Result<TrackSummary> TrackFrames(const Searcher& searcher,
                                 FrameSource& frames,
                                 const TrackOptions& options,
                                 const std::function<Status(const TrackFrame&)>& on_frame,
                                 bool progress) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "invalid track options (see the line above)");
  }
  const auto start = std::chrono::steady_clock::now();
  Tracker tracker(searcher, options);
  TrackSummary summary;
  const int64_t hint = frames.size_hint();
  Progress bar("track", hint > 0 ? static_cast<uint64_t>(hint) : 0, progress, "frames");
  bar.QuietUnlessSlow(start);
  std::vector<TrackFrame> held;  // offline: every frame until the last
  Frame frame;
  while (true) {
    Result<bool> next = frames.Next(&frame);
    if (!next.ok()) return next.status();
    if (!*next) break;
    TrackFrame answer = tracker.Answer(frame);
    ++summary.frames;
    switch (answer.found) {
      case FoundBy::kNone:
        ++summary.found_none;
        break;
      case FoundBy::kFull:
        ++summary.found_full;
        break;
      case FoundBy::kLocal:
        ++summary.found_local;
        break;
      case FoundBy::kCarried:
        ++summary.found_carried;
        break;
    }
    if (options.smoothing == Smoothing::kOff) {
      answer.chosen = answer.matches.empty() ? -1 : 0;
    } else {
      answer.chosen = tracker.ChooseOnline(answer);
    }
    tracker.Chose(answer);
    if (options.smoothing == Smoothing::kOffline) {
      held.push_back(std::move(answer));
    } else {
      tracker.Pose(&answer);
      tracker.FilterOnline(&answer);
      HANDDB_RETURN_IF_ERROR(on_frame(answer));
    }
    if (hint > 0 && bar.done() + 1 > static_cast<uint64_t>(hint)) bar.SetTotal(bar.done() + 1);
    bar.Add();
  }
  if (options.smoothing == Smoothing::kOffline) {
    std::vector<std::vector<PoseCandidate>> candidates;
    for (const TrackFrame& f : held) candidates.push_back(CandidatesOf(f.matches));
    const std::vector<int> choice = ChooseByDynamicProgramming(candidates, options.transition);
    std::vector<std::optional<Keypoints2d>> keypoints(held.size());
    std::vector<std::optional<Keypoints3d>> keypoints_3d(held.size());
    std::vector<double> times(held.size());
    for (size_t i = 0; i < held.size(); ++i) {
      held[i].chosen = choice[i];
      tracker.Pose(&held[i]);
      if (held[i].has_pose) {
        keypoints[i] = held[i].keypoints_image_px;
        keypoints_3d[i] = held[i].keypoints_3d;
      }
      times[i] = held[i].time_s;
    }
    keypoints = FilterSequence(keypoints, times, options.keypoint_filter);
    keypoints_3d = FilterSequence(keypoints_3d, times, options.keypoint_filter);
    for (size_t i = 0; i < held.size(); ++i) {
      if (keypoints[i]) held[i].keypoints_image_px = *keypoints[i];
      if (keypoints_3d[i]) held[i].keypoints_3d = *keypoints_3d[i];
      HANDDB_RETURN_IF_ERROR(on_frame(held[i]));
    }
  }
  bar.Finish();
  summary.seconds = SecondsSince(start);
  return summary;
}

}  // namespace handdb
