// `handdb evaluate DB --photos DIR` (issue 16): shape accuracy of the search on real photographs.
//
// DIR follows the common image-folder convention: one sub-folder per expected shape, named like a
// shape of the database (DIR/asl-3/IMG_0001.JPG). Every photo goes through the real photo path
// (skin segmentation, Canny, the database's normalisation) and the exact search; a photo counts as
// right at k when its expected shape is among the shapes of the top-k matches. Photos without a
// usable query (no hand found, unreadable) count as misses at every k and keep their one-line
// error. The chance baseline at k is the mean over photos of P(a view of the right shape among
// the first k of a uniformly random ordering of the database's (view, roll) pairs), i.e.
// 1 - C(n - m, k) / C(n, k) with n virtual views and m of them of the right shape
// (ChanceOfCorrectInTopN of evaluate/evaluate.h).
//
// Like evaluate/evaluate.h the scoring knows nothing of images: the per-photo work yields a
// PhotoOutcome (shapes of the top matches) and FinishPhotoReport aggregates outcomes, so the
// aggregation is tested on hand-made outcomes.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/view.h"
#include "query/searcher.h"

namespace handdb {

struct PhotoItem {
  std::filesystem::path path;  // as found under the photo directory
  std::string relative;        // "<shape>/<file>", the photo's name in reports
  std::string expected_shape;
};

struct PhotoSet {
  std::filesystem::path dir;
  std::vector<PhotoItem> photos;             // sorted by relative path
  std::vector<std::string> skipped_folders;  // not a shape of the database (skip_unknown)
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

// What one photo's query gave.
struct PhotoOutcome {
  std::string photo;  // PhotoItem::relative
  std::string expected_shape;
  std::string error;                      // no usable query (empty: fine)
  std::vector<std::string> match_shapes;  // shapes of the top matches, best first
  std::vector<double> match_distances;    // their D_c, px
  view_id_t top1_view = kInvalidViewId;   // for the contact sheets
  float top1_roll_angle = 0;              // radians
  double input_seconds = 0;               // image -> query points
  double search_seconds = 0;
  std::vector<Point2f> query_points;  // normalised frame, px (for the contact sheets)
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

// Label of failed inputs in the confusion matrix and the per-shape table.
constexpr const char* kNoHandLabel = "no hand";

struct PhotoReport {
  std::string database;
  uint64_t database_views = 0;
  uint32_t database_rolls = 0;
  uint64_t database_virtual_views = 0;
  // Virtual views per shape name, for the chance baseline.
  std::map<std::string, uint64_t> virtual_views_per_shape;
  std::string photos_dir;
  std::vector<std::string> skipped_folders;
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
  double input_seconds = 0;
  double search_seconds = 0;
  double queries_per_second = 0;             // searches only, per search thread-second
  double end_to_end_queries_per_second = 0;  // input + search
  double wall_seconds = 0;                   // set by the caller
  int threads = 0;                           // set by the caller
};

// Sorts the outcomes and computes every derived field. THROW_CHECKs that ks are positive.
void FinishPhotoReport(PhotoReport* report);

// Image -> query points in the normalised frame, px (the CLI passes the photo path).
using PhotoPointsFn = std::function<Result<std::vector<Point2f>>(const PhotoItem&)>;

struct PhotoEvaluationOptions {
  int num_threads = -1;  // photos searched in parallel, one search thread each
  bool progress = true;
  bool Check() const;
};

// Runs every photo (ParallelFor over photos) and fills report->outcomes with the top
// max(ks) matches, then FinishPhotoReport. The report's database fields are filled here.
Result<PhotoReport> EvaluatePhotos(const Searcher& searcher,
                                   const PhotoSet& photos,
                                   const PhotoPointsFn& points_fn,
                                   const PhotoEvaluationOptions& options);

nlohmann::json PhotoReportToJson(const PhotoReport& report);  // schemas/photo_evaluation
std::string PhotoReportToText(const PhotoReport& report);

// confusion.png, successes.png and failures.png (a handful of photos each, from as many shapes as
// possible) in `dir`.
Status WritePhotoReportImages(const PhotoReport& report,
                              const Searcher& searcher,
                              const PhotoSet& photos,
                              const std::filesystem::path& dir);
// The confusion matrix alone (rows expected, columns top-1 shape, counts, row-normalised shade).
Status WriteConfusionPng(const std::filesystem::path& path, const PhotoReport& report);

}  // namespace handdb
