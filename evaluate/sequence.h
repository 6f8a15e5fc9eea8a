// Scoring a predictor on test sequences (generator/testset/sequence.h; docs/evaluation.md,
// "Sequences"): every frame of every sequence, in order, goes through a predictor -- a callable,
// so a tracker plugs in without this library knowing it -- and its answers are scored per
// sequence and overall:
//  - per-frame keypoint error over the frames where the hand is wholly in the picture: the
//    root-relative 3D error of evaluate/metrics.h (KeypointError, hand sizes, and in the truth's
//    wrist-to-middle-knuckle lengths) and the 2D error in the frame's px (mean over the 21
//    keypoints, also divided by the hand size of evaluate/photo_keypoints.h);
//  - jitter: the mean norm of the second difference k[t+1] - 2 k[t] + k[t-1] of the keypoints,
//    over every three consecutive frames where the hand is wholly in the picture and was found,
//    for the prediction and for the truth over the same frames (its floor: the truth moves too);
//    in 3D root-relative (hand sizes) and in 2D px;
//  - recovery: each time the hand comes back after a stretch of frames in which it was not wholly
//    in the picture and at least one in which it was wholly out, whether the predictor found it
//    within `recovery_frames` frames from the first frame it is wholly back (found, and found
//    with a 2D error of at most `recovery_max_error` hand sizes);
//  - frames where the hand is wholly out but the predictor answered (false finds);
//  - frames per second of the predictor.
//
// The baseline predictor answers each frame alone with SearchPicture (pose/picture_search.h):
// the top match, or its pose fit when the search options carry the database's rig.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "evaluate/evaluate.h"
#include "evaluate/metrics.h"
#include "pose/picture_search.h"

namespace handdb {

// One frame's truth.
struct SequenceFrameTruth {
  uint32_t view_index = 0;  // in SequenceTestSet::testset.views
  uint32_t sequence = 0;
  uint32_t frame = 0;
  double time = 0;
  bool clutter = false;
  int in_picture = 0;     // keypoints inside the picture
  bool visible = false;   // all 21 inside
  Keypoints keypoints{};  // normalised frame (of the unshifted label render), as TestView::truth
  std::array<Point2f, kNumKeypoints> keypoints_px{};  // the photo's px
  std::filesystem::path photo;                        // absolute; empty without photos
};

struct SequenceTruth {
  uint32_t id = 0;
  bool clutter = false;
  std::vector<SequenceFrameTruth> frames;  // in frame order
};

struct SequenceTestSet {
  TestSet testset;
  double fps = 0;
  std::vector<SequenceTruth> sequences;
};

// Whether DIR/testset.json (or the file) is a sequence test set (has "sequence"). Errors: the
// file cannot be read or parsed.
Result<bool> IsSequenceTestSet(const std::filesystem::path& dir_or_file);

// ReadTestSet plus the sequence fields; kInvalidArgument when the test set has none, and for
// frames that do not make whole sequences (a frame missing or twice).
Result<SequenceTestSet> ReadSequenceTestSet(const std::filesystem::path& dir_or_file);

struct SequenceFrameInput {
  uint32_t sequence = 0;
  uint32_t frame = 0;
  double time = 0;
  bool first = false;  // the first frame of a sequence: a tracker starts afresh
  std::filesystem::path photo;
};

struct FramePrediction {
  bool found = false;
  Keypoints keypoints{};  // 3D in the picture's normalised frame, as a match's label keypoints
  std::array<Point2f, kNumKeypoints> keypoints_px{};  // the frame's px
  JointVector joint_angles{};
};

// Frames come in order, sequence after sequence. An error ends the evaluation; a frame without
// a hand is an answer with found = false.
using FramePredictor = std::function<Result<FramePrediction>(const SequenceFrameInput&)>;

// A whole sequence at once, for a predictor that needs the frames after a frame to answer it (a
// tracker's offline smoothing): the prediction of every frame of `frames` (one sequence, in
// order) and, in *seconds, the time each took; frame_done() once per frame as it is answered
// (progress). An error ends the evaluation.
using SequencePredictor = std::function<Result<std::vector<FramePrediction>>(
    const std::vector<SequenceFrameInput>& frames,
    double fps,
    std::vector<double>* seconds,
    const std::function<void()>& frame_done)>;

// A frame predictor as a sequence predictor: frame after frame.
SequencePredictor FrameByFrame(FramePredictor predictor);

// Each frame alone: SearchPicture of its photo, the top match (its fit when options.rig is set
// and the fit succeeded). No hand in the picture (kNoHand) is "not found". The searcher must
// outlive the predictor.
FramePredictor MakeFrameAlonePredictor(const Searcher& searcher, PictureSearchOptions options);

struct SequenceScoreOptions {
  int recovery_frames = 5;          // found again within this many frames after a return
  double recovery_max_error = 0.2;  // 2D error (hand sizes) a recovery must be within
  int max_sequences = 0;            // score only the first N sequences (0: all)
  bool progress = true;
  bool Check() const;
};

struct FrameOutcome {
  uint32_t frame = 0;
  bool visible = false;
  int in_picture = 0;
  bool found = false;
  // NaN unless visible and found.
  double error_3d = std::numeric_limits<double>::quiet_NaN();     // hand sizes
  double error_3d_wm = std::numeric_limits<double>::quiet_NaN();  // wrist-to-middle-MCP lengths
  double error_2d_px = std::numeric_limits<double>::quiet_NaN();
  double error_2d = std::numeric_limits<double>::quiet_NaN();  // hand sizes (keypoint bbox)
  double seconds = 0;
};

struct SequenceStats {
  int64_t frames = 0;
  int64_t visible = 0;  // wholly in the picture
  int64_t absent = 0;   // wholly out
  int64_t found_visible = 0;
  int64_t false_finds = 0;  // found while wholly out
  Summary error_3d, error_3d_wm, error_2d_px, error_2d;
  int64_t jitter_triples = 0;
  // Mean norms of second differences; NaN without triples.
  double jitter_3d = std::numeric_limits<double>::quiet_NaN();  // hand sizes per frame^2
  double jitter_3d_truth = std::numeric_limits<double>::quiet_NaN();
  double jitter_2d_px = std::numeric_limits<double>::quiet_NaN();
  double jitter_2d_px_truth = std::numeric_limits<double>::quiet_NaN();
  int64_t returns = 0;
  int64_t recovered = 0;    // found within recovery_frames with error <= recovery_max_error
  int64_t found_again = 0;  // found within recovery_frames at all
  double seconds = 0;
  double frames_per_second = 0;
};

struct SequenceOutcome {
  uint32_t id = 0;
  bool clutter = false;
  std::vector<FrameOutcome> frames;
  SequenceStats stats;
};

// Per-frame outcome, then the statistics, of one sequence (pure: tests give hand-made
// predictions). predictions and seconds have one entry per frame.
SequenceOutcome ScoreSequence(const SequenceTruth& truth,
                              const std::vector<FramePrediction>& predictions,
                              const std::vector<double>& seconds,
                              const SequenceScoreOptions& options);

struct SequenceReport {
  std::string database;
  std::string testset;
  std::string predictor;  // e.g. "each frame alone"
  double fps = 0;         // of the sequences
  SequenceScoreOptions options;
  std::vector<SequenceOutcome> sequences;
  SequenceStats overall;  // over every frame, triple and return of all sequences
  double wall_seconds = 0;
};

// The statistics over several sequences' frames (errors over all frames, jitter over all triples,
// recoveries over all returns); what SequenceReport::overall holds.
SequenceStats CombineSequenceStats(const std::vector<SequenceOutcome>& sequences,
                                   const SequenceScoreOptions& options);

// Runs `predictor` over every frame (progress with ETA) and scores them.
Result<SequenceReport> EvaluateSequences(const SequenceTestSet& testset,
                                         const SequencePredictor& predictor,
                                         const SequenceScoreOptions& options);
Result<SequenceReport> EvaluateSequences(const SequenceTestSet& testset,
                                         const FramePredictor& predictor,
                                         const SequenceScoreOptions& options);

nlohmann::json SequenceReportToJson(const SequenceReport& report);  // sequence_evaluation.schema
std::string SequenceReportToText(const SequenceReport& report);

}  // namespace handdb
