// Evaluation split into parts (issue 7, `handdb evaluate --slurm`, docs/cluster.md): each Slurm
// array task scores a deterministic slice of the selected test views (EvaluateViews) and writes the
// per-view outcomes to WORK/parts/part-0000i.json (schemas/evaluation_part.schema.json); the final
// job merges the parts and aggregates them with FinishReport, the same function a local
// `handdb evaluate` ends with, so both give the same report.
//
// Every part records a fingerprint of what it was computed from: the database's manifest bytes
// (which list every shard's checksum), the testset.json bytes, the options that change scores, and
// the number of tasks. A part whose fingerprint, task or views do not fit is refused with one line
// naming the file, never silently merged.
#pragma once

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "evaluate/evaluate.h"

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

// Task 7's part is "part-00007": the stem of its file and (`handdb evaluate --slurm`) of its
// Slurm task's log and failure marker.
inline constexpr char kPartPrefix[] = "part-";
std::string PartName(uint32_t task);

// WORK/parts/part-00007.json
std::filesystem::path PartPath(const std::filesystem::path& work_dir, uint32_t task);

struct EvaluationPart {
  EvaluationFingerprint fingerprint;
  uint32_t task = 0;
  uint32_t num_tasks = 1;
  int threads = 1;
  double started_at = 0;  // Unix time, seconds
  double finished_at = 0;
  std::vector<ViewOutcome> views;  // query_points are not stored
};

nlohmann::json PartToJson(const EvaluationPart& part);
// `where` names the source in errors. The JSON must already match the schema.
Result<EvaluationPart> PartFromJson(const nlohmann::json& doc, const std::string& where);
// Schema-checked, atomic.
Status WritePart(const std::filesystem::path& path, const EvaluationPart& part);

// What a part of one evaluation must be.
struct PartExpectation {
  EvaluationFingerprint fingerprint;
  uint32_t task = 0;
  std::vector<uint32_t> slice;  // TaskSlice of the selection
  size_t num_criteria = 0;
};
// Reads and checks a part: schema, fingerprint (naming what differs: database, test set, options
// or task count), task number, exactly the views of its slice, one rank per criterion.
// kNotFound when the file does not exist.
Result<EvaluationPart> ReadPart(const std::filesystem::path& path, const PartExpectation& expect);

// Reads and checks parts 0..num_tasks-1 of WORK (num_tasks from the fingerprint), puts their views
// into `report` (which StartReport made), and calls FinishReport. The report's thread count is the
// largest of the tasks'; wall_seconds spans from the first task's start to the last one's end.
Status MergeParts(const std::filesystem::path& work_dir,
                  const EvaluationFingerprint& fingerprint,
                  std::span<const uint32_t> selected,
                  EvaluationReport* report);

}  // namespace handdb
