// Video tracking (docs/track.md): a picture's answer that uses the frames before it. Per frame,
// the picture's evidence once (photo/: edges and landmarks, pose/picture_search.h's pieces), then
//  - a local search (query/: exact over the neighbourhood of the previous answer,
//    track/neighbourhood.h), falling back to the full search when there is no previous answer
//    (the first frame, a frame without a hand before), when the local best D_c exceeds
//    `refind_ratio` times the last frames' (plus a margin), or every `full_every` frames, so
//    the tracker re-initialises by itself;
//  - or the previous frame's answer carried, when the frame's edges are the previous frame's
//    (a repeated frame);
// then one candidate of the frame's top k chosen over time (track/smoothing.h: dynamic
// programming, online over a look-back window or offline over the whole sequence), fitted to
// the picture when the database has its rig (pose/fit_matches.h), and its keypoints filtered
// (smoothing off: each frame's best as it is, unfiltered).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "pose/picture_search.h"
#include "query/searcher.h"
#include "track/frames.h"
#include "track/neighbourhood.h"
#include "track/smoothing.h"

namespace handdb {

enum class Smoothing { kOff, kOnline, kOffline };
std::string_view SmoothingName(Smoothing s);  // "off", "online", "offline"
Result<Smoothing> ParseSmoothing(std::string_view name);

// How a frame's matches were found.
enum class FoundBy { kNone, kFull, kLocal, kCarried };
std::string_view FoundByName(FoundBy f);  // "none", "full", "local", "carried"

struct TrackOptions {
  // The picture -> evidence -> search -> landmark re-rank -> fit of every frame; search.top_k is
  // the candidates per frame the smoother chooses among.
  PictureSearchOptions picture;
  bool local_search = true;  // false: a full search every frame
  // A frame's landmark network runs once, on the crop around the last frame's joints
  // (PictureOptions::landmark_start), while it finds a hand there (presence >= 0.5), as MediaPipe
  // Hands tracks one; false: each frame's landmarks are found as a picture alone's.
  bool landmark_tracking = true;
  NeighbourhoodOptions local;
  // A full search at least every this many frames (0: only when the local search fails).
  int full_every = 30;
  // The local search fails when its best D_c exceeds refind_ratio times the largest best D_c of
  // the last 4 frames answered plus refind_margin_px: a hand that is lost or moved past the
  // neighbourhood shows as a jump of D_c, while the slow changes of a tracked hand, and the rise
  // and fall of D_c as it turns between two stored rolls (the last frames' largest), stay
  // within it.
  double refind_ratio = 1.5;
  double refind_margin_px = 1.0;
  Smoothing smoothing = Smoothing::kOnline;
  int window = 8;  // online: the frames the dynamic programming looks back over, this one included
  TransitionCosts transition;
  KeypointFilterOptions keypoint_filter;
  // Keep each video frame's pixels in its TrackFrame (for an overlay of a video; a folder's
  // frames are read again from their files).
  bool keep_pixels = false;
  bool Check() const;
};

// One frame's answer (schemas/track_frame.schema.json).
struct TrackFrame {
  int64_t index = 0;
  double time_s = 0;
  std::string source;  // the picture's path, or VIDEO#index
  FoundBy found = FoundBy::kNone;
  Status error;  // with kNone: why (a missing or unreadable frame, no hand, a failed search)
  std::optional<PictureEvidence> evidence;
  std::vector<Match> matches;  // the frame's top k, best first
  bool landmarks_used = false;
  int chosen = -1;  // the smoother's choice among `matches`
  // The chosen match's fit (with the database's rig): fit.fits[0] fits matches[chosen].
  PictureFit fit;
  // The answer's 21 keypoints in the frame's px and in 3D (the picture's normalised frame with
  // depth, as a label's keypoints): the fit's when fitted, else the chosen match's, filtered over
  // time (smoothing off: as they are).
  bool has_pose = false;
  std::array<Point2f, kNumKeypoints> keypoints_image_px{};
  Keypoints3d keypoints_3d{};
  // With TrackOptions::keep_pixels, a video frame's pixels (8-bit BGR, rows packed).
  std::vector<uint8_t> frame_bgr;
  int frame_width = 0, frame_height = 0;
  uint64_t pairs_searched = 0;  // (view, roll, hand) pairs the search bounded
  double search_seconds = 0;
  double seconds = 0;  // the frame's whole work
};

struct TrackSummary {
  int64_t frames = 0;
  int64_t found_full = 0, found_local = 0, found_carried = 0, found_none = 0;
  double seconds = 0;
};

// Runs the tracker over `frames`, calling on_frame once per frame in order: as each is answered
// (smoothing off or online), or all after the last (offline). An error of on_frame stops the run
// and is returned; a frame's own error never does. Errors: kInvalidArgument (options), the
// source's.
Result<TrackSummary> TrackFrames(const Searcher& searcher,
                                 FrameSource& frames,
                                 const TrackOptions& options,
                                 const std::function<Status(const TrackFrame&)>& on_frame,
                                 bool progress = false);

}  // namespace handdb
