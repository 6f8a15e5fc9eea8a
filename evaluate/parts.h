// Evaluation split into parts (`handdb evaluate --slurm`, docs/cluster.md): each Slurm
// array task scores a deterministic slice of the selected test views (EvaluateViews) and writes the
// per-view outcomes to WORK/parts/part-0000i.json (schemas/evaluation_part.schema.json); the final
// job merges the parts and aggregates them with FinishReport, the same function a local
// `handdb evaluate` ends with, so both give the same report.
//
// Every part records a fingerprint of what it was computed from: the database's manifest bytes
// (which list every shard's checksum), the testset.json bytes, the options that change scores, and
// the number of tasks. A part whose fingerprint, task or views do not fit is refused with one line
// naming the file, never silently merged.
//
// A photo evaluation (`handdb evaluate DB --photos DIR --slurm`, evaluate/photos.h) is split the
// same way: task i scores the photos at positions k with k % N == i (ScorePhotos), the merge
// aggregates with FinishPhotoReport; its fingerprint covers the photo list instead of a test set.
#pragma once

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "evaluate/evaluate.h"
#include "evaluate/photos.h"

namespace handdb {

struct EvaluationFingerprint {
  std::string value;      // 16 lowercase hex digits: XXH3-64 of inputs.dump()
  nlohmann::json inputs;  // {database_manifest_xxh3, testset_xxh3, input, options, tasks}
};

// The options that change an evaluation's scores or its choice of test views (not threads, not
// progress), as JSON with doubles stored exactly.
nlohmann::json ScoringOptionsToJson(const EvaluationOptions& options);

EvaluationFingerprint MakeEvaluationFingerprint(const std::string& database_manifest_xxh3,
                                                const std::string& testset_xxh3,
                                                QueryInput input,
                                                const EvaluationOptions& options,
                                                uint32_t num_tasks);
// The same from files: DB_DIR/manifest.json and testset.file.
Result<EvaluationFingerprint> ComputeEvaluationFingerprint(const std::filesystem::path& db_dir,
                                                           const TestSet& testset,
                                                           QueryInput input,
                                                           const EvaluationOptions& options,
                                                           uint32_t num_tasks);

// Task `task` of `num_tasks` takes the selected views at positions k with k % num_tasks == task:
// interleaved, so basic and PCA views (and cheap and costly queries) spread evenly over tasks.
std::vector<uint32_t> TaskSlice(std::span<const uint32_t> selected,
                                uint32_t task,
                                uint32_t num_tasks);
// The same over positions 0..num_items-1 (a photo evaluation's photos).
std::vector<uint32_t> TaskSlice(size_t num_items, uint32_t task, uint32_t num_tasks);

// Task 7's part is "part-00007": the stem of its file and (`handdb evaluate --slurm`) of its
// Slurm task's log and failure marker.
inline constexpr char kPartPrefix[] = "part-";
std::string PartName(uint32_t task);

// WORK/parts/part-00007.json
std::filesystem::path PartPath(const std::filesystem::path& work_dir, uint32_t task);

// What every part says of the task that wrote it (test-set and photo evaluations alike).
struct PartHeader {
  EvaluationFingerprint fingerprint;
  uint32_t task = 0;
  uint32_t num_tasks = 1;
  int threads = 1;
  double started_at = 0;  // Unix time, seconds
  double finished_at = 0;
};

// One API for the parts of both evaluations, over the row type a part holds (ViewOutcome of a
// test set, PhotoOutcome of photos). PartRow<Row> is what differs: the document's format, schema
// and key of its rows (also the noun of messages), the row's JSON codec, and what the rows of a
// task must be (Expected) to belong to this evaluation.
template <typename Row>
struct PartRow;

template <>
struct PartRow<ViewOutcome> {
  static constexpr char kFormat[] = "handdb-evaluation-part";
  static constexpr char kSchema[] = "evaluation_part.schema.json";
  static constexpr char kKey[] = "views";
  struct Expected {
    std::vector<uint32_t> slice;  // TaskSlice of the selection: the test-set index of each view
    size_t num_criteria = 0;      // ranks per view, one per criterion
  };
  static size_t Count(const Expected& e) { return e.slice.size(); }
  // query_points are not stored.
  static nlohmann::json ToJson(const ViewOutcome& v);
  // The JSON must already match the schema: a missing field throws json::exception, which
  // PartFromJson reports naming the file.
  static Result<ViewOutcome> FromJson(const nlohmann::json& j, const std::string& where);
  // Row k of `file` against the slice: its test view and its number of ranks.
  static Status Check(const ViewOutcome& v,
                      size_t k,
                      const Expected& expect,
                      const std::string& file);
};

template <>
struct PartRow<PhotoOutcome> {
  static constexpr char kFormat[] = "handdb-photo-evaluation-part";
  static constexpr char kSchema[] = "photo_evaluation_part.schema.json";
  static constexpr char kKey[] = "photos";
  struct Expected {
    std::vector<std::string> photos;  // the relative names of the task's slice, in order
  };
  static size_t Count(const Expected& e) { return e.photos.size(); }
  static nlohmann::json ToJson(const PhotoOutcome& o) { return o.ToJson(); }
  static Result<PhotoOutcome> FromJson(const nlohmann::json& j, const std::string& where) {
    return PhotoOutcome::FromJson(j, where);
  }
  static Status Check(const PhotoOutcome& o,
                      size_t k,
                      const Expected& expect,
                      const std::string& file);
};

template <typename Row>
struct Part : PartHeader {
  std::vector<Row> rows;  // query_points are not stored
};
using EvaluationPart = Part<ViewOutcome>;
using PhotoEvaluationPart = Part<PhotoOutcome>;

// What a part of one evaluation must be.
template <typename Row>
struct PartExpectation {
  EvaluationFingerprint fingerprint;
  uint32_t task = 0;
  typename PartRow<Row>::Expected rows;
};
// Task `task` of a test-set evaluation of `selected` views, scored on `num_criteria` criteria.
PartExpectation<ViewOutcome> ExpectedPart(const EvaluationFingerprint& fingerprint,
                                          uint32_t task,
                                          std::span<const uint32_t> selected,
                                          size_t num_criteria);
// Task `task` of a photo evaluation of `photos`.
PartExpectation<PhotoOutcome> ExpectedPart(const EvaluationFingerprint& fingerprint,
                                           uint32_t task,
                                           const PhotoSet& photos);

template <typename Row>
nlohmann::json PartToJson(const Part<Row>& part);
// `where` names the source in errors. The JSON must already match the schema.
template <typename Row>
Result<Part<Row>> PartFromJson(const nlohmann::json& doc, const std::string& where);
// Schema-checked (PartRow<Row>::kSchema), atomic.
template <typename Row>
Status WritePart(const std::filesystem::path& path, const Part<Row>& part);
// Reads and checks a part: schema, fingerprint (naming what differs: database, test set or photos,
// options or task count), task number, exactly the rows of its slice (PartRow<Row>::Check).
// kNotFound when the file does not exist.
template <typename Row>
Result<Part<Row>> ReadPart(const std::filesystem::path& path, const PartExpectation<Row>& expect);

// Reads and checks parts 0..num_tasks-1 of WORK (num_tasks from the fingerprint), puts their views
// into `report` (which StartReport made), and calls FinishReport. The report's thread count is the
// largest of the tasks'; wall_seconds spans from the first task's start to the last one's end.
Status MergeParts(const std::filesystem::path& work_dir,
                  const EvaluationFingerprint& fingerprint,
                  std::span<const uint32_t> selected,
                  EvaluationReport* report);
// The same for a photo evaluation: outcomes into `report` (which StartPhotoReport made), then
// FinishPhotoReport.
Status MergeParts(const std::filesystem::path& work_dir,
                  const EvaluationFingerprint& fingerprint,
                  const PhotoSet& photos,
                  PhotoReport* report);

// ---- Photo evaluations ------------------------------------------------------------------------

// The options that change a photo evaluation's outcomes: the hand, the matches searched per photo
// and `query_options` (how a picture becomes a query: the CLI's photo-path flags, resolved).
nlohmann::json PhotoScoringOptionsToJson(const PhotoEvaluationOptions& options,
                                         const nlohmann::json& query_options);

// XXH3-64 (hex) of the photo list: each photo's path relative to DIR and its size in bytes, in
// order. Cheap (no photo is read), and it changes when a photo is added, removed, renamed or
// replaced by a file of another size; kIoError naming a photo whose size cannot be read.
Result<std::string> PhotoListChecksum(const PhotoSet& photos);

EvaluationFingerprint MakePhotoEvaluationFingerprint(const std::string& database_manifest_xxh3,
                                                     const std::string& photos_xxh3,
                                                     const std::string& keypoints_xxh3,
                                                     const nlohmann::json& scoring_options,
                                                     uint32_t num_tasks);
// The same from files: DB_DIR/manifest.json, the photos' sizes and photos.keypoints_file (its
// bytes; "" without one).
Result<EvaluationFingerprint> ComputePhotoEvaluationFingerprint(
    const std::filesystem::path& db_dir,
    const PhotoSet& photos,
    const nlohmann::json& scoring_options,
    uint32_t num_tasks);

}  // namespace handdb
