// `handdb evaluate DB SEQUENCE-TESTSET`: a test set made of sequences (generator/testset/
// sequence.h) is scored with the sequence metrics of evaluate/sequence.h -- per-frame keypoint
// error, jitter, recovery after the hand left the picture, frames/s -- for the tracker of
// `handdb track` (track/tracker.h), or for the baseline that answers each frame alone, as
// `handdb query` answers a photo (docs/evaluation.md, "Sequences").
#include <CLI/CLI.hpp>
#include <cstdio>
#include <string>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "cli/cli_util.h"
#include "cli/evaluate_cli.h"
#include "evaluate/sequence.h"
#include "evaluate/sequence_track.h"
#include "pose/picture_search.h"

namespace handdb::cli {

void SequenceEvaluateFlags::Add(CLI::App& app) {
  const char* group = "Sequence test sets (docs/evaluation.md, Sequences)";
  app.add_option("--recovery-frames",
                 options.recovery_frames,
                 "a return of the hand counts as recovered when it is found within this many "
                 "frames")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str()
      ->group(group);
  app.add_option("--recovery-max-error",
                 options.recovery_max_error,
                 "... with a 2D keypoint error of at most this many hand sizes")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str()
      ->group(group);
  app.add_option("--predictor",
                 predictor,
                 "what answers the frames: tracker (handdb track, with its defaults) or alone "
                 "(each frame searched on its own, as handdb query answers a photo)")
      ->check(CLI::IsMember({"tracker", "alone"}))
      ->capture_default_str()
      ->group(group);
  app.add_option("--smooth", smooth, "the tracker's smoothing: online, offline or off")
      ->check(CLI::IsMember({"online", "offline", "off"}))
      ->capture_default_str()
      ->group(group);
  app.add_option("--sequences", options.max_sequences, "score only the first N sequences (0: all)")
      ->check(CLI::NonNegativeNumber)
      ->group(group);
}

int RunEvaluateSequences(EvaluateSlurmRequest request,
                         const SequenceEvaluateFlags& sequence_flags,
                         bool input_given) {
  EvaluateFlags& flags = request.flags;
  if (input_given && flags.input != "photo") {
    std::fprintf(stderr,
                 "handdb evaluate: %s is a sequence test set, scored from its photos (--input "
                 "photo, the default for sequences)\n",
                 request.testset.c_str());
    return kExitUsage;
  }
  if (!request.plots_dir.empty()) {
    std::fprintf(stderr, "handdb evaluate: --plots does not apply to a sequence test set\n");
    return kExitUsage;
  }
  flags.input = "photo";
  if (!flags.Finish("evaluate", request.quiet)) return flags.failure_exit_code;
  SequenceScoreOptions options = sequence_flags.options;
  options.progress = !request.quiet;
  if (!options.Check()) {
    std::fprintf(stderr, "handdb evaluate: bad sequence options\n");
    return kExitUsage;
  }

  auto testset = ReadSequenceTestSet(request.testset);
  if (!testset.ok()) return Fail("evaluate", testset.status());
  auto searcher = Searcher::Open(request.db, flags.searcher_options());
  if (!searcher.ok()) return Fail("evaluate", searcher.status());
  WarnIfTestSetMatchesDatabase(request.db, testset->testset);
  if (!flags.LoadFit(request.db, "evaluate")) return kExitError;

  // Each frame alone, as `handdb query` answers a photo of a right hand (the renders' hand).
  PictureSearchOptions search;
  search.picture.edges.kind = QueryInputKind::kPhoto;
  search.picture.landmarker = flags.landmarker;
  search.landmark_rank = flags.options.landmark_rank;
  search.rig = flags.options.fit_rig;
  search.fit = flags.options.fit;
  if (!search.Check()) {
    std::fprintf(stderr, "handdb evaluate: bad picture search options\n");
    return kExitUsage;
  }
  const char* fitted = search.rig != nullptr ? "fitted" : "top match";
  std::string predictor_name;
  auto report = [&]() -> Result<SequenceReport> {
    if (sequence_flags.predictor == "alone") {
      predictor_name = std::string("each frame alone (SearchPicture, ") + fitted + ")";
      return EvaluateSequences(*testset, MakeFrameAlonePredictor(**searcher, search), options);
    }
    TrackOptions track;
    track.picture = search;
    track.smoothing = *ParseSmoothing(sequence_flags.smooth);
    predictor_name = "tracker (smoothing " + sequence_flags.smooth + ", " + fitted + ")";
    return EvaluateSequences(*testset, MakeTrackerPredictor(**searcher, track), options);
  }();
  if (!report.ok()) return Fail("evaluate", report.status());
  report->database = request.db;
  report->testset = request.testset;
  report->predictor = predictor_name;
  if (!request.quiet) std::printf("%s", SequenceReportToText(*report).c_str());
  if (!request.json_out.empty()) {
    const nlohmann::json doc = SequenceReportToJson(*report);
    Status s = ValidateJson(doc, "sequence_evaluation.schema.json", request.json_out);
    if (s.ok()) s = WriteJsonFileAtomic(request.json_out, doc);
    if (!s.ok()) return Fail("evaluate", s);
  }
  return kExitOk;
}

}  // namespace handdb::cli
