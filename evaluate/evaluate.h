// `handdb evaluate DB TESTSET`: runs every test view of a held-out test set
// (generator/testset/testset.h, schemas/testset.schema.json) through the real search and scores the
// matches with the rules of evaluate/metrics.h (docs/evaluation.md):
//  - the paper's Table 1: how many test views have their highest-ranking correct match at rank 1,
//    2-4, 5-16, 17-64, 65-256, 257-1024, > 1024;
//  - success@(d, n) for n = 1, 10, 100 over a grid of joint distances d;
//  - root-relative 3D keypoint error of the top-1 match, of the best of the top 10 and of the best
//    (view, roll) of the whole database (the floor), in hand sizes and in wrist-to-middle-knuckle
//    lengths; a slot for the error of a fitted pose;
//  - queries per second.
// Ranks are exact: each query is first searched for the top `first_k` (the timed search); when a
// criterion has no correct match among them, the query is searched again for the top `max_rank`,
// which the pruned search also returns exactly, so a rank is either exact or "> max_rank". Every
// correct (view, roll) pair of the database is counted from the labels first (linear, cheap): a
// view with none skips the deeper search, and the counts give the chance baseline.
//
// This library knows nothing of images: the caller turns a test view into query edge points (the
// CLI uses the converter for clean label renders and the photo path for photos).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "evaluate/metrics.h"
#include "format/roll.h"
#include "generator/hand/database_rig.h"
#include "photo/image_edges.h"
#include "pose/fit_matches.h"
#include "pose/landmark_rank.h"
#include "query/searcher.h"

namespace handdb {

// One held-out test view's ground truth.
struct TestView {
  uint32_t id = 0;
  bool basic = false;  // a named basic shape
  std::string shape_name;
  PoseForEval truth;            // joints, view direction, camera roll, normalised keypoints
  std::filesystem::path label;  // label EXR (absolute)
  std::filesystem::path photo;  // photo PNG (absolute; empty if none)
};

struct TestSet {
  std::filesystem::path dir;
  std::filesystem::path file;  // the testset.json read (its bytes are part of a Slurm fingerprint)
  std::string name;
  uint64_t seed = 0;
  std::string hand_model_sha256;
  HandAxes axes;
  bool clutter = false;
  bool forearm = false;  // the photos show a forearm (test-set photo.forearm)
  std::vector<TestView> views;
};

// Reads DIR/testset.json (or the JSON file itself), schema-checked; errors name the file.
Result<TestSet> ReadTestSet(const std::filesystem::path& dir_or_file);

enum class QueryInput { kClean, kPhoto };
const char* QueryInputName(QueryInput input);

// Every file `input` reads for the test views at `positions` (labels for clean queries, photos
// for photo queries) is a regular file: kNotFound / kIoError name the first that is missing or
// is a device, FIFO or directory, so a broken test set is refused instead of scored as misses.
Status CheckTestSetInputs(const TestSet& testset,
                          QueryInput input,
                          std::span<const uint32_t> positions);

// A test view's query: edge points in the normalised frame (px) and, for a photo, the photo
// path's whole evidence, whose hand landmarks (if any) re-rank the search (pose/landmark_rank.h).
struct TestQuery {
  std::vector<Point2f> points;
  std::optional<PictureEvidence> picture;
  explicit TestQuery(std::vector<Point2f> p) : points(std::move(p)) {}
  explicit TestQuery(PictureEvidence q) : points(q.edges.points_px()), picture(std::move(q)) {}
};

// Turns a test view into its query. An error (e.g. no hand found in a photo) is recorded for
// that view, which then counts as having no correct match.
using QueryPointsFn = std::function<Result<TestQuery>(const TestView&)>;

struct EvaluationOptions {
  CorrectnessOptions correctness;                        // the main criterion (Table 1)
  std::vector<double> d_grid_deg = {5, 10, 15, 20, 30};  // success@(d, n) for each d
  std::vector<int64_t> success_n = {1, 10, 100};
  int first_k = 100;                  // depth of the timed search
  int64_t max_rank = kMaxBinnedRank;  // exact ranks up to this (Table 1 needs 1024)
  int num_threads = -1;               // search threads
  int max_views = 0;                  // evaluate only the first N test views (0: all)
  int stride = 1;                     // evaluate every stride-th test view (0, s, 2s, ...)
  bool progress = true;
  // Photo queries with landmarks are re-ranked by them, as `handdb query` does; the model's path
  // ("" when none) is part of a Slurm run's fingerprint.
  LandmarkRankOptions landmark_rank;
  std::string landmark_model;
  // The floor of the keypoint error: per test view, the best (view, roll) of the whole database
  // (KeypointFloorIndex; on the paper database about a millisecond per test view).
  bool keypoint_floor = true;
  // The database's rig: set, a photo query's matches are fitted to its landmarks as `handdb
  // query --fit` does, and ViewOutcome::fitted_keypoint_error is the answer's error after the
  // fit (the chosen fit, or the top match where nothing was fitted).
  std::shared_ptr<const DatabaseRig> fit_rig;
  MatchFitOptions fit;
  bool Check() const;
};

// P(at least one of `correct` marked items among the first n of a random ordering of `total`).
double ChanceOfCorrectInTopN(uint64_t total, uint64_t correct, uint64_t n);

// A criterion's name and its rules; `basic_only` criteria skip PCA-sampled test views.
struct Criterion {
  std::string name;
  CorrectnessOptions options;
  bool basic_only = false;
};
// The criteria an evaluation scores: [0] the main one, then "same-shape" (basic views, the paper's
// rule), then one per d of the grid ("d=15").
std::vector<Criterion> MakeCriteria(const EvaluationOptions& options);

struct MatchBrief {
  view_id_t view_id = kInvalidViewId;
  roll_id_t roll = 0;
  double distance = 0;
  std::string shape_name;
  CorrectnessDetail detail;  // against the main criterion
};

struct ViewOutcome {
  uint32_t test_id = 0;
  uint32_t testset_index = 0;  // position in TestSet::views (reports list views in this order)
  bool basic = false;
  std::string shape_name;
  std::string error;           // query could not be made (empty: fine)
  std::vector<int64_t> ranks;  // per criterion; kNoCorrectMatch = none within max_rank;
                               // -1 = criterion does not apply to this view
  // Root-relative 3D keypoint errors in hand sizes (KeypointError); NaN when not measured.
  double top1_keypoint_error = std::numeric_limits<double>::quiet_NaN();
  double best10_keypoint_error = std::numeric_limits<double>::quiet_NaN();
  // The best (view, roll) of the whole database (KeypointFloorIndex), whether or not the query
  // could be made; NaN when the evaluation ran without the floor.
  double floor_keypoint_error = std::numeric_limits<double>::quiet_NaN();
  // The error of a pose fitted to the test view (pose/fit.h), for the caller that fits; NaN: none.
  double fitted_keypoint_error = std::numeric_limits<double>::quiet_NaN();
  // The truth's wrist-to-middle-knuckle length (WristToMiddleMcp), px of the normalised frame: an
  // error e in hand sizes is e * kNormalisedDiameter / this in these lengths.
  double wrist_to_middle_mcp_px = std::numeric_limits<double>::quiet_NaN();
  std::optional<MatchBrief> top1;
  double input_seconds = 0;   // image -> query points
  double search_seconds = 0;  // the timed top-first_k search
  bool deep_search = false;   // a second search for the rank was needed
  size_t num_query_points = 0;
  int64_t num_correct = 0;             // correct (view, roll) pairs in the database, main criterion
  std::vector<int64_t> correct_pairs;  // the same per criterion (0 where it does not apply)
  std::vector<Point2f> query_points;   // for example sheets (not kept in Slurm parts)
};

struct SuccessCell {
  std::string criterion;
  double d_deg = 0;
  int64_t n = 0;
  double rate = 0;  // over the views the criterion applies to
  int64_t views = 0;
};

struct EvaluationReport {
  std::string database;
  uint64_t database_views = 0;
  uint32_t database_rolls = 0;
  uint64_t database_virtual_views = 0;
  std::string testset;
  uint64_t testset_seed = 0;
  QueryInput input = QueryInput::kClean;
  EvaluationOptions options;
  std::vector<Criterion> criteria;
  std::vector<ViewOutcome> views;
  std::vector<RankTable> tables;  // per criterion (views the criterion applies to)
  // Per criterion: applicable views with no correct pair in the whole database (a PCA shape far
  // from every database shape); they are part of the last bin of the table.
  std::vector<int64_t> views_without_correct;
  std::vector<SuccessCell> success;
  // Keypoint errors in hand sizes and, `_wm`, in wrist-to-middle-knuckle lengths of the truth.
  Summary top1_keypoint_error;
  Summary best10_keypoint_error;
  Summary floor_keypoint_error;   // count 0: run without the floor
  Summary fitted_keypoint_error;  // count 0: no fitted poses
  Summary top1_keypoint_error_wm;
  Summary best10_keypoint_error_wm;
  Summary floor_keypoint_error_wm;
  Summary fitted_keypoint_error_wm;
  // Chance baseline, main criterion, per success_n: the mean over test views of P(a correct match
  // in the top n of a uniformly random ordering of the database).
  std::vector<double> chance_success;
  double mean_correct_per_view = 0;
  int64_t failed_inputs = 0;  // views whose query could not be made
  int64_t deep_searches = 0;
  double search_seconds = 0;  // sum of timed searches
  double input_seconds = 0;
  double wall_seconds = 0;
  double queries_per_second = 0;             // timed searches only
  double end_to_end_queries_per_second = 0;  // input + timed search
  int threads = 0;
};

// An evaluation is (1) the per-view work, EvaluateViews, over any subset of the selected test
// views, and (2) the aggregation, FinishReport, over the outcomes of all of them. `Evaluate` does
// both in one process; `handdb evaluate --slurm` runs (1) in array tasks, each writing its outcomes
// to a part file (evaluate/parts.h), and (2) in the final job over the merged parts. Both paths
// call the same two functions, which is why their reports are identical (docs/cluster.md lists the
// run-specific timing fields that differ).

// Positions (in testset.views) of the test views an evaluation scores: every stride-th view, then
// at most max_views of them.
std::vector<uint32_t> SelectTestViews(const TestSet& testset, const EvaluationOptions& options);

// The report's header: database and test-set description, options, criteria, thread count. No
// views yet.
EvaluationReport StartReport(const Database& db,
                             const TestSet& testset,
                             QueryInput input,
                             const EvaluationOptions& options);

// Scores the test views at `positions` (in testset.views), in that order, with the criteria of
// MakeCriteria(options). Outcomes carry their query points (for example sheets).
Result<std::vector<ViewOutcome>> EvaluateViews(const Searcher& searcher,
                                               const TestSet& testset,
                                               const QueryPointsFn& query_points,
                                               const EvaluationOptions& options,
                                               std::span<const uint32_t> positions);

// Sorts report->views by testset_index and computes everything derived from them: Table 1 per
// criterion, success@(d, n), keypoint-error summaries, the chance baseline, counts of failed inputs
// and deeper searches, summed input and search times and the queries-per-second rates.
// wall_seconds is left to the caller (it is the one number that depends on how the work ran).
void FinishReport(EvaluationReport* report);

// StartReport + EvaluateViews(SelectTestViews) + FinishReport, timed.
Result<EvaluationReport> Evaluate(const Searcher& searcher,
                                  const TestSet& testset,
                                  QueryInput input,
                                  const QueryPointsFn& query_points,
                                  const EvaluationOptions& options);

nlohmann::json ReportToJson(const EvaluationReport& report);
std::string ReportToText(const EvaluationReport& report);

// rank_histogram.png, keypoint_error_cdf.png, successes.png, failures.png in `dir`. The example
// sheets show each chosen view's query points; a view without them (a report merged from Slurm
// parts) gets them from `query_points` when given (the same function the evaluation used).
Status WriteReportPlots(const EvaluationReport& report,
                        const Searcher& searcher,
                        const TestSet& testset,
                        const std::filesystem::path& dir,
                        const QueryPointsFn& query_points = nullptr);

}  // namespace handdb
