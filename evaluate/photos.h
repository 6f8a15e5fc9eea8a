// `handdb evaluate DB --photos DIR` (docs/evaluation.md): shape accuracy of the search on real
// photographs.
//
// DIR follows the common image-folder convention: one sub-folder per expected shape, named like a
// shape of the database (DIR/asl-3/IMG_0001.JPG). Every photo goes through the real photo path
// (skin segmentation, Canny, the database's normalisation) and the exact search, as the right
// hand, the left hand (mirrored query) or either hand (both searched, one merged top-k; the
// setting `handdb query` defaults to); a photo counts as right at k when its expected shape is
// among the shapes of the top-k matches. The search ranks shapes by default (one match per
// shape, SearchOptions::max_per_shape = 1: the top k are the k nearest shapes, the usual top-k
// accuracy of a classifier); ranking views instead (max_per_shape = 0) counts the shapes among
// the k nearest (view, roll, hand) triples, which are often k rolls of one view. Photos without a
// usable query (no hand found, unreadable) count as misses at every k and keep their one-line
// error. The chance baseline at k is the mean over photos of the same event for a uniformly
// random ordering of the database's (view, roll) pairs: ranking views, 1 - C(n - m, k) / C(n, k)
// with n virtual views and m of them of the right shape (ChanceOfCorrectInTopN of
// evaluate/evaluate.h); ranking shapes, P(the right shape among the first k distinct shapes of
// that ordering) (ChanceOfShapeAmongFirstK, k / number of shapes when all are the same size).
// Photos with 2D keypoint annotations (evaluate/photo_keypoints.h) also get the 2D keypoint error
// of the top-1 match and of the best of the top 10 (ranking shapes: of the 10 nearest shapes'
// best views).
//
// Like evaluate/evaluate.h an evaluation is (1) the per-photo work, ScorePhotos, over any subset
// of the photos, and (2) the aggregation, FinishPhotoReport, over the outcomes of all of them.
// EvaluatePhotos does both in one process; `handdb evaluate --photos DIR --slurm` runs (1) in
// array tasks that write their outcomes to part files (evaluate/parts.h) and (2) in the merge job,
// so both give the same report. The aggregation is tested on hand-made outcomes.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "evaluate/metrics.h"
#include "evaluate/photo_keypoints.h"
#include "format/view.h"
#include "photo/image_edges.h"
#include "pose/landmark_rank.h"
#include "query/searcher.h"

namespace handdb {

struct PhotoItem {
  std::filesystem::path path;  // as found under the photo directory
  std::string relative;        // "<shape>/<file>", the photo's name in reports
  std::string expected_shape;
  std::optional<PhotoKeypoints> keypoints;  // its 2D annotation (--keypoints), if any
};

struct PhotoSet {
  std::filesystem::path dir;
  std::vector<PhotoItem> photos;             // sorted by relative path
  std::vector<std::string> skipped_folders;  // not a shape of the database (skip_unknown)
  std::filesystem::path keypoints_file;      // empty: no annotations (AttachPhotoKeypoints)
};

// Image files the photo path reads, by extension (case-insensitive): jpg, jpeg, png, bmp, tif,
// tiff, webp.
bool IsPhotoFile(const std::filesystem::path& path);

// Lists DIR/<shape>/<photo>. Errors (one line naming the path): kNotFound (no such directory),
// kInvalidArgument (a folder named after no shape of `shape_names`, unless skip_unknown; no
// photos at all). Files directly in DIR and non-image files (SOURCE.md, LICENSE) are ignored.
Result<PhotoSet> ListPhotoFolders(const std::filesystem::path& dir,
                                  std::span<const std::string> shape_names,
                                  bool skip_unknown);

// Gives each photo of `set` its annotation from `file`. An annotation must name a photo of the
// set, or an image file in a folder the listing skipped (not counted then); anything else is an
// error naming the file and the key (kInvalidArgument): an annotation of a photo that is not
// there is most likely a misspelt path, and a silently unscored photo would make the keypoint
// error describe other photos than the user thinks.
Status AttachPhotoKeypoints(const PhotoKeypointFile& file, PhotoSet* set);

// The 2D keypoint result of an annotated photo with a match (evaluate/photo_keypoints.h).
struct PhotoKeypointResult {
  double hand_size_px = 0;                        // of the annotation
  std::array<double, kNumKeypoints> top1_px{};    // per keypoint distance; NaN: not visible
  std::array<double, kNumKeypoints> best10_px{};  // the same for the best of the top 10
  int best10_rank = 0;                            // 1-based rank of that match
  double top1_error() const;                      // MeanKeypointError(top1_px, hand_size_px)
  double best10_error() const;
};

// What one photo's query gave.
struct PhotoOutcome {
  std::string photo;  // PhotoItem::relative
  std::string expected_shape;
  std::string error;                      // no usable query (empty: fine)
  std::vector<std::string> match_shapes;  // shapes of the top matches, best first
  std::vector<double> match_distances;    // their D_c, px
  std::vector<Hand> match_hands;          // kRight, or kLeft when the mirrored query matched
  view_id_t top1_view = kInvalidViewId;   // for the contact sheets
  roll_id_t top1_roll = 0;
  // The top-1 match's 21 keypoints in the photo's pixels (mirrored back for a left hand): the
  // frame and the code of `handdb query --json`'s keypoints_image_px. Empty without a match.
  std::vector<Point2f> top1_keypoints_px;
  int annotated_keypoints = 0;                   // visible annotated keypoints (0: not annotated)
  std::optional<PhotoKeypointResult> keypoints;  // annotated photos with a match
  double input_seconds = 0;                      // image -> query points
  double search_seconds = 0;
  std::vector<Point2f> query_points;  // normalised frame, px (contact sheets; not in JSON)

  // The per-photo object of the report and of Slurm parts (schemas/photo_evaluation.schema.json
  // #/$defs/photo); FromJson takes a document that matches it. Doubles and floats round-trip
  // exactly.
  nlohmann::json ToJson() const;
  static Result<PhotoOutcome> FromJson(const nlohmann::json& j, const std::string& where);
};

// 1-based rank of the first match of the expected shape; 0 when none (or an error).
int ShapeRank(const PhotoOutcome& outcome);

// Per expected shape.
struct PhotoShapeRow {
  std::string shape;
  int64_t photos = 0;
  std::vector<int64_t> hits;  // per k of PhotoReport::ks
  std::string top_wrong;      // most frequent wrong top-1 shape ("no hand" for failed inputs;
                              // ties: alphabetical); empty if every top-1 is right
  int64_t top_wrong_count = 0;
};

// Matches searched per photo: top-1/5/10 shape accuracy and the best of the top 10 (keypoints).
inline constexpr int kPhotoMatches = 10;

// P(shape `shape` is among the first k distinct shapes met in a uniformly random ordering of all
// the views counted in `views_per_shape`): each shape s first appears at T_s, the minimum of its
// n_s i.i.d. uniform times, independent across shapes, so the probability is
// integral of n_r (1-t)^(n_r - 1) P(fewer than k other T_s < t) dt, computed by adaptive Simpson
// (the inner probability by a Poisson-binomial recursion). k / S for S shapes of equal size.
double ChanceOfShapeAmongFirstK(const std::map<std::string, uint64_t>& views_per_shape,
                                const std::string& shape,
                                int k);

// Label of failed inputs in the confusion matrix and the per-shape table.
constexpr const char* kNoHandLabel = "no hand";

// The 2D keypoint error of one match choice (top-1 or best of the top 10) over annotated photos.
struct PhotoKeypointSummary {
  Summary error;  // per-photo mean error (hand sizes), over annotated photos with a match
  // Per kPckThresholds: the share of all visible annotated keypoints within t hand sizes; the
  // keypoints of annotated photos without a usable query count as missed.
  std::vector<double> pck;
};

struct PhotoReport {
  std::string database;
  uint64_t database_views = 0;
  uint32_t database_rolls = 0;
  uint64_t database_virtual_views = 0;
  // Virtual views per shape name, for the chance baseline.
  std::map<std::string, uint64_t> virtual_views_per_shape;
  std::string photos_dir;
  std::vector<std::string> skipped_folders;
  Hand hand = Hand::kRight;   // the search setting
  int top_k = kPhotoMatches;  // matches searched per photo (at least every k of ks)
  int max_per_shape = 1;      // 1: shapes ranked (one match each); 0: views ranked
  // How pictures became queries (the CLI's photo-path flags), recorded as given; may be null.
  nlohmann::json query_options;
  std::string keypoints_file;  // --keypoints; empty: none
  std::vector<int> ks = {1, 5, 10};
  std::vector<PhotoOutcome> outcomes;  // sorted by photo name (FinishPhotoReport)

  // Derived by FinishPhotoReport:
  std::vector<int64_t> hits;          // per k
  std::vector<double> accuracy;       // per k, over all photos
  std::vector<double> chance;         // per k
  std::vector<PhotoShapeRow> shapes;  // expected shapes, alphabetical
  // Rows: expected shapes (as `shapes`); columns: those shapes, then the other top-1 shapes
  // (alphabetical), then kNoHandLabel if a photo failed. confusion[row][col] = photos.
  std::vector<std::string> confusion_rows;
  std::vector<std::string> confusion_cols;
  std::vector<std::vector<int64_t>> confusion;
  int64_t failed_inputs = 0;
  int64_t top1_left = 0;   // photos whose top-1 match is a left hand (mirrored query)
  int64_t top1_right = 0;  // ... a right hand
  int64_t annotated_photos = 0;
  int64_t annotated_failed = 0;  // annotated photos without a usable query
  PhotoKeypointSummary top1_keypoints;
  PhotoKeypointSummary best10_keypoints;
  double input_seconds = 0;
  double search_seconds = 0;
  double queries_per_second = 0;             // searches only, per search thread-second
  double end_to_end_queries_per_second = 0;  // input + search
  double wall_seconds = 0;                   // set by the caller
  int threads = 0;                           // set by the caller
};

// Sorts the outcomes and computes every derived field. THROW_CHECKs that ks are in 1..top_k.
void FinishPhotoReport(PhotoReport* report);

// Image -> its evidence (edge points in the normalised frame, the map back to the image's
// pixels, the hand landmarks); the CLI reads the photo as `handdb query` does.
using PhotoQueryFn = std::function<Result<PictureEvidence>(const PhotoItem&)>;

struct PhotoEvaluationOptions {
  // The search's setting, as SearchOptions::hand (whose default it shares); `handdb evaluate`
  // passes its --hand, which defaults to either like `handdb query`'s.
  Hand hand = SearchOptions{}.hand;
  // 1: rank shapes (one match per shape: top-k = the k nearest shapes); 0: rank views (top-k =
  // the shapes of the k nearest (view, roll, hand) triples). `handdb evaluate --rank`.
  int max_per_shape = 1;
  int num_threads = -1;  // photos searched in parallel, one search thread each
  bool progress = true;
  // A photo with hand landmarks (PictureOptions::landmarker) is re-ranked by them
  // (pose/landmark_rank.h), as `handdb query` does.
  LandmarkRankOptions landmark_rank;
  bool Check() const;
};

// The report's header: database, photos, options, thread count. No outcomes yet.
PhotoReport StartPhotoReport(const Database& db,
                             const PhotoSet& photos,
                             const PhotoEvaluationOptions& options);

// Scores the photos at `positions` (in photos.photos), in that order (ParallelFor over them):
// the top max(ks) matches, the top-1 keypoints in the photo's pixels, the 2D keypoint result of
// annotated photos. Outcomes carry their query points (for the contact sheets).
Result<std::vector<PhotoOutcome>> ScorePhotos(const Searcher& searcher,
                                              const PhotoSet& photos,
                                              const PhotoQueryFn& query_fn,
                                              const PhotoEvaluationOptions& options,
                                              std::span<const uint32_t> positions);

// StartPhotoReport + ScorePhotos(every photo) + FinishPhotoReport, timed.
Result<PhotoReport> EvaluatePhotos(const Searcher& searcher,
                                   const PhotoSet& photos,
                                   const PhotoQueryFn& query_fn,
                                   const PhotoEvaluationOptions& options);

nlohmann::json PhotoReportToJson(const PhotoReport& report);  // schemas/photo_evaluation
std::string PhotoReportToText(const PhotoReport& report);

// confusion.png, successes.png and failures.png (a handful of photos each, from as many shapes as
// possible) in `dir`. A shown photo without query points (a report merged from Slurm parts) gets
// them from `query_fn` when given (the function the evaluation used).
Status WritePhotoReportImages(const PhotoReport& report,
                              const Searcher& searcher,
                              const PhotoSet& photos,
                              const std::filesystem::path& dir,
                              const PhotoQueryFn& query_fn = nullptr);
// The confusion matrix alone (rows expected, columns top-1 shape, counts, row-normalised shade).
Status WriteConfusionPng(const std::filesystem::path& path, const PhotoReport& report);

}  // namespace handdb
