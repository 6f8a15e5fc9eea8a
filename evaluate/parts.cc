#include "evaluate/parts.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>

#include "base/json_number.h"
#include "base/json_schema.h"
#include "cluster/slurm.h"
#include "format/shard_layout.h"

namespace handdb {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

// The first key of two objects whose values differ, for messages ("first_k: 100 vs 50").
std::string FirstDifference(const json& part, const json& expected) {
  for (const auto& [key, value] : expected.items()) {
    if (!part.contains(key)) return key + ": missing";
    if (part.at(key) != value) return key + ": " + part.at(key).dump() + " vs " + value.dump();
  }
  for (const auto& [key, value] : part.items()) {
    if (!expected.contains(key)) return key + ": not an option of this evaluation";
  }
  return "";
}

// One input of a fingerprint that a part must share with this evaluation, and how to say that it
// does not: describe(got, want) completes "<file>: a part of another evaluation: ...".
struct InputCheck {
  std::string key;
  std::function<std::string(const json& got, const json& want)> describe;
};

// "made from another database (manifest xxh3 <got>, this one's is <want>)" for `prefix` =
// "made from another database (manifest xxh3 ".
std::function<std::string(const json&, const json&)> ChecksumDiffers(std::string prefix) {
  return [prefix](const json& got, const json& want) {
    auto text = [](const json& j) {
      const std::string v = j.is_string() ? j.get<std::string>() : j.dump();
      return v.empty() ? std::string("none") : v;
    };
    return prefix + text(got) + ", this one's is " + text(want) + ")";
  };
}

// The inputs of a part's fingerprint against this evaluation's: the `checks` first, then the
// options, the task count and the fingerprint value; one line naming `file` and what differs.
Status CheckPartInputs(const std::string& file,
                       const EvaluationFingerprint& part,
                       uint32_t part_tasks,
                       const EvaluationFingerprint& expected,
                       const std::vector<InputCheck>& checks) {
  const json& got = part.inputs;
  const json& want = expected.inputs;
  auto mismatch = [&](const std::string& what) {
    return Status(StatusCode::kInvalidArgument,
                  file + ": a part of another evaluation: " + what +
                      "; delete it (or use another --work directory) and run again");
  };
  for (const InputCheck& c : checks) {
    const json missing = "?";
    const json& g = got.contains(c.key) ? got.at(c.key) : missing;
    if (g != want.at(c.key)) return mismatch(c.describe(g, want.at(c.key)));
  }
  if (!got.contains("options") || got.at("options") != want.at("options")) {
    return mismatch("made with other evaluation options (" +
                    FirstDifference(got.value("options", json::object()), want.at("options")) +
                    ")");
  }
  if (got.value("tasks", json()) != want.at("tasks") ||
      part_tasks != want.at("tasks").get<uint32_t>()) {
    return mismatch("made for a split into " + std::to_string(part_tasks) + " tasks, not " +
                    want.at("tasks").dump());
  }
  if (part.value != expected.value) {
    return mismatch("fingerprint " + part.value + ", expected " + expected.value);
  }
  return Status::Ok();
}

Status MissingPart(const fs::path& path, uint32_t task, uint32_t num_tasks) {
  return Status(StatusCode::kNotFound,
                path.string() + ": missing (task " + std::to_string(task) + " of " +
                    std::to_string(num_tasks) + " has not written its part)");
}

EvaluationFingerprint FingerprintOf(json inputs) {
  EvaluationFingerprint f;
  f.inputs = std::move(inputs);
  const std::string text = f.inputs.dump();
  f.value = shard::ChecksumHex(shard::Checksum(text.data(), text.size()));
  return f;
}

// The fingerprint inputs, besides options and task count, that a part of each kind must share.
template <typename Row>
std::vector<InputCheck> InputChecks();

template <>
std::vector<InputCheck> InputChecks<ViewOutcome>() {
  return {{"database_manifest_xxh3", ChecksumDiffers("made from another database (manifest xxh3 ")},
          {"testset_xxh3", ChecksumDiffers("made from another test set (testset.json xxh3 ")},
          {"input", [](const json& got, const json& want) {
             return "made with --input " + got.get<std::string>() + ", not " +
                    want.get<std::string>();
           }}};
}

template <>
std::vector<InputCheck> InputChecks<PhotoOutcome>() {
  return {{"database_manifest_xxh3", ChecksumDiffers("made from another database (manifest xxh3 ")},
          {"photos_xxh3", ChecksumDiffers("made from other photos (photo names and sizes xxh3 ")},
          {"keypoints_xxh3", ChecksumDiffers("made with another --keypoints file (xxh3 ")}};
}

// Parts 0..num_tasks-1 of WORK (num_tasks from the fingerprint), each read and checked against
// `expect(task)`, their rows appended to `rows` in task order; `threads` the largest of the
// tasks' and `wall_seconds` from the first task's start to the last one's end.
template <typename Row>
Status ReadAllParts(const fs::path& work_dir,
                    const EvaluationFingerprint& fingerprint,
                    const std::function<PartExpectation<Row>(uint32_t task)>& expect,
                    std::vector<Row>* rows,
                    int* threads,
                    double* wall_seconds) {
  const uint32_t num_tasks = fingerprint.inputs.at("tasks").get<uint32_t>();
  double first_start = std::numeric_limits<double>::infinity();
  double last_finish = -std::numeric_limits<double>::infinity();
  *threads = 0;
  for (uint32_t task = 0; task < num_tasks; ++task) {
    const fs::path path = PartPath(work_dir, task);
    auto part = ReadPart(path, expect(task));
    if (!part.ok()) {
      if (part.status().code() == StatusCode::kNotFound) return MissingPart(path, task, num_tasks);
      return part.status();
    }
    first_start = std::min(first_start, part->started_at);
    last_finish = std::max(last_finish, part->finished_at);
    *threads = std::max(*threads, part->threads);
    for (auto& r : part->rows) rows->push_back(std::move(r));
  }
  *wall_seconds = num_tasks > 0 ? std::max(0.0, last_finish - first_start) : 0;
  return Status::Ok();
}

}  // namespace

json PartRow<ViewOutcome>::ToJson(const ViewOutcome& v) {
  json j = {{"index", v.testset_index},
            {"id", v.test_id},
            {"basic", v.basic},
            {"shape_name", v.shape_name},
            {"ranks", v.ranks},
            {"correct_pairs", v.correct_pairs},
            {"num_correct", v.num_correct},
            {"top1_keypoint_error", NumberOrNull(v.top1_keypoint_error)},
            {"best10_keypoint_error", NumberOrNull(v.best10_keypoint_error)},
            {"floor_keypoint_error", NumberOrNull(v.floor_keypoint_error)},
            {"fitted_keypoint_error", NumberOrNull(v.fitted_keypoint_error)},
            {"wrist_to_middle_mcp_px", NumberOrNull(v.wrist_to_middle_mcp_px)},
            {"input_seconds", v.input_seconds},
            {"search_seconds", v.search_seconds},
            {"deep_search", v.deep_search},
            {"query_points", v.num_query_points}};
  if (!v.error.empty()) j["error"] = v.error;
  if (v.top1) {
    const CorrectnessDetail& d = v.top1->detail;
    j["top1"] = {{"view_id", v.top1->view_id},
                 {"roll", v.top1->roll},
                 {"distance", v.top1->distance},
                 {"shape_name", v.top1->shape_name},
                 {"joint_distance_deg", d.joint_distance_deg},
                 {"direction_deg", d.direction_deg},
                 {"roll_deg", d.roll_deg},
                 {"shape_ok", d.shape_ok},
                 {"direction_ok", d.direction_ok},
                 {"roll_ok", d.roll_ok}};
  }
  return j;
}

Result<ViewOutcome> PartRow<ViewOutcome>::FromJson(const json& j, const std::string& /*where*/) {
  ViewOutcome v;
  v.testset_index = j.at("index").get<uint32_t>();
  v.test_id = j.at("id").get<uint32_t>();
  v.basic = j.at("basic").get<bool>();
  v.shape_name = j.at("shape_name").get<std::string>();
  if (j.contains("error")) v.error = j.at("error").get<std::string>();
  v.ranks = j.at("ranks").get<std::vector<int64_t>>();
  v.correct_pairs = j.at("correct_pairs").get<std::vector<int64_t>>();
  v.num_correct = j.at("num_correct").get<int64_t>();
  v.top1_keypoint_error = NumberOrNaN(j.at("top1_keypoint_error"));
  v.best10_keypoint_error = NumberOrNaN(j.at("best10_keypoint_error"));
  v.floor_keypoint_error = NumberOrNaN(j.at("floor_keypoint_error"));
  v.fitted_keypoint_error = NumberOrNaN(j.at("fitted_keypoint_error"));
  v.wrist_to_middle_mcp_px = NumberOrNaN(j.at("wrist_to_middle_mcp_px"));
  v.input_seconds = j.at("input_seconds").get<double>();
  v.search_seconds = j.at("search_seconds").get<double>();
  v.deep_search = j.at("deep_search").get<bool>();
  v.num_query_points = j.at("query_points").get<size_t>();
  if (j.contains("top1")) {
    const json& t = j.at("top1");
    MatchBrief m;
    m.view_id = t.at("view_id").get<view_id_t>();
    m.roll = t.at("roll").get<roll_id_t>();
    m.distance = t.at("distance").get<double>();
    m.shape_name = t.at("shape_name").get<std::string>();
    m.detail.joint_distance_deg = t.at("joint_distance_deg").get<double>();
    m.detail.direction_deg = t.at("direction_deg").get<double>();
    m.detail.roll_deg = t.at("roll_deg").get<double>();
    m.detail.shape_ok = t.at("shape_ok").get<bool>();
    m.detail.direction_ok = t.at("direction_ok").get<bool>();
    m.detail.roll_ok = t.at("roll_ok").get<bool>();
    v.top1 = m;
  }
  return v;
}

json ScoringOptionsToJson(const EvaluationOptions& options) {
  const CorrectnessOptions& c = options.correctness;
  return {{"joint_distance", std::string(JointDistanceKindName(c.joint_distance))},
          {"max_joint_distance_deg", c.max_joint_distance_deg},
          {"max_direction_deg", c.max_direction_deg},
          {"max_roll_deg", c.max_roll_deg},
          {"roll_compare", c.roll_compare == RollCompare::kAligned ? "aligned" : "label"},
          {"same_shape", c.same_shape},
          {"d_grid_deg", options.d_grid_deg},
          {"success_n", options.success_n},
          {"first_k", options.first_k},
          {"max_rank", options.max_rank},
          {"max_views", options.max_views},
          {"stride", options.stride},
          {"landmark_model", options.landmark_model},
          {"landmark_weight", options.landmark_rank.weight}};
}

EvaluationFingerprint MakeEvaluationFingerprint(const std::string& database_manifest_xxh3,
                                                const std::string& testset_xxh3,
                                                QueryInput input,
                                                const EvaluationOptions& options,
                                                uint32_t num_tasks) {
  return FingerprintOf({{"database_manifest_xxh3", database_manifest_xxh3},
                        {"testset_xxh3", testset_xxh3},
                        {"input", QueryInputName(input)},
                        {"options", ScoringOptionsToJson(options)},
                        {"tasks", num_tasks}});
}

Result<EvaluationFingerprint> ComputeEvaluationFingerprint(const fs::path& db_dir,
                                                           const TestSet& testset,
                                                           QueryInput input,
                                                           const EvaluationOptions& options,
                                                           uint32_t num_tasks) {
  auto manifest = shard::FileChecksum((db_dir / "manifest.json").string());
  if (!manifest.ok()) return manifest.status();
  auto ts = shard::FileChecksum(testset.file.string());
  if (!ts.ok()) return ts.status();
  return MakeEvaluationFingerprint(
      shard::ChecksumHex(*manifest), shard::ChecksumHex(*ts), input, options, num_tasks);
}

std::vector<uint32_t> TaskSlice(std::span<const uint32_t> selected,
                                uint32_t task,
                                uint32_t num_tasks) {
  THROW_CHECK_GE(num_tasks, 1u);
  std::vector<uint32_t> slice;
  for (size_t k = task; k < selected.size(); k += num_tasks) slice.push_back(selected[k]);
  return slice;
}

std::vector<uint32_t> TaskSlice(size_t num_items, uint32_t task, uint32_t num_tasks) {
  THROW_CHECK_GE(num_tasks, 1u);
  std::vector<uint32_t> slice;
  for (size_t k = task; k < num_items; k += num_tasks) slice.push_back(static_cast<uint32_t>(k));
  return slice;
}

std::string PartName(uint32_t task) { return SlurmTaskName(kPartPrefix, task); }

fs::path PartPath(const fs::path& work_dir, uint32_t task) {
  return work_dir / "parts" / (PartName(task) + ".json");
}

Status PartRow<ViewOutcome>::Check(const ViewOutcome& v,
                                   size_t k,
                                   const Expected& expect,
                                   const std::string& file) {
  if (v.testset_index != expect.slice[k]) {
    return Status(StatusCode::kInvalidArgument,
                  file + ": views[" + std::to_string(k) + "] is test view " +
                      std::to_string(v.testset_index) + ", expected " +
                      std::to_string(expect.slice[k]));
  }
  if (v.ranks.size() != expect.num_criteria || v.correct_pairs.size() != expect.num_criteria) {
    return Status(StatusCode::kInvalidArgument,
                  file + ": views[" + std::to_string(k) + "]: " + std::to_string(v.ranks.size()) +
                      " ranks and " + std::to_string(v.correct_pairs.size()) +
                      " correct-pair counts, expected " + std::to_string(expect.num_criteria) +
                      " (one per criterion)");
  }
  return Status::Ok();
}

Status PartRow<PhotoOutcome>::Check(const PhotoOutcome& o,
                                    size_t k,
                                    const Expected& expect,
                                    const std::string& file) {
  if (o.photo != expect.photos[k]) {
    return Status(StatusCode::kInvalidArgument,
                  file + ": photos[" + std::to_string(k) + "] is " + o.photo + ", expected " +
                      expect.photos[k]);
  }
  return Status::Ok();
}

PartExpectation<ViewOutcome> ExpectedPart(const EvaluationFingerprint& fingerprint,
                                          uint32_t task,
                                          std::span<const uint32_t> selected,
                                          size_t num_criteria) {
  PartExpectation<ViewOutcome> expect;
  expect.fingerprint = fingerprint;
  expect.task = task;
  expect.rows.slice = TaskSlice(selected, task, fingerprint.inputs.at("tasks").get<uint32_t>());
  expect.rows.num_criteria = num_criteria;
  return expect;
}

PartExpectation<PhotoOutcome> ExpectedPart(const EvaluationFingerprint& fingerprint,
                                           uint32_t task,
                                           const PhotoSet& photos) {
  PartExpectation<PhotoOutcome> expect;
  expect.fingerprint = fingerprint;
  expect.task = task;
  const uint32_t num_tasks = fingerprint.inputs.at("tasks").get<uint32_t>();
  for (uint32_t i : TaskSlice(photos.photos.size(), task, num_tasks)) {
    expect.rows.photos.push_back(photos.photos[i].relative);
  }
  return expect;
}

template <typename Row>
json PartToJson(const Part<Row>& part) {
  json rows = json::array();
  for (const Row& r : part.rows) rows.push_back(PartRow<Row>::ToJson(r));
  return {{"format", PartRow<Row>::kFormat},
          {"version", 1},
          {"fingerprint", part.fingerprint.value},
          {"inputs", part.fingerprint.inputs},
          {"task", part.task},
          {"tasks", part.num_tasks},
          {"threads", part.threads},
          {"started_at", part.started_at},
          {"finished_at", part.finished_at},
          {PartRow<Row>::kKey, std::move(rows)}};
}

template <typename Row>
Result<Part<Row>> PartFromJson(const json& doc, const std::string& where) {
  try {
    Part<Row> part;
    part.fingerprint.value = doc.at("fingerprint").get<std::string>();
    part.fingerprint.inputs = doc.at("inputs");
    part.task = doc.at("task").get<uint32_t>();
    part.num_tasks = doc.at("tasks").get<uint32_t>();
    part.threads = doc.at("threads").get<int>();
    part.started_at = doc.at("started_at").get<double>();
    part.finished_at = doc.at("finished_at").get<double>();
    const json& rows = doc.at(PartRow<Row>::kKey);
    for (size_t k = 0; k < rows.size(); ++k) {
      auto r = PartRow<Row>::FromJson(
          rows.at(k), where + ": " + PartRow<Row>::kKey + "[" + std::to_string(k) + "]");
      if (!r.ok()) return r.status();
      part.rows.push_back(std::move(*r));
    }
    return part;
  } catch (const json::exception& e) {
    return Status(StatusCode::kSchemaViolation, where + ": " + e.what());
  }
}

template <typename Row>
Status WritePart(const fs::path& path, const Part<Row>& part) {
  const json doc = PartToJson(part);
  HANDDB_RETURN_IF_ERROR(ValidateJson(doc, PartRow<Row>::kSchema, path.string()));
  std::error_code ec;
  fs::create_directories(path.parent_path(), ec);
  if (ec) {
    return Status(StatusCode::kIoError,
                  path.parent_path().string() + ": cannot create: " + ec.message());
  }
  return WriteJsonFileAtomic(path, doc);
}

template <typename Row>
Result<Part<Row>> ReadPart(const fs::path& path, const PartExpectation<Row>& expect) {
  auto doc = ReadJsonFile(path, PartRow<Row>::kSchema);
  if (!doc.ok()) return doc.status();
  auto part = PartFromJson<Row>(*doc, path.string());
  if (!part.ok()) return part.status();
  const std::string file = path.string();
  HANDDB_RETURN_IF_ERROR(CheckPartInputs(
      file, part->fingerprint, part->num_tasks, expect.fingerprint, InputChecks<Row>()));
  if (part->task != expect.task) {
    return Status(StatusCode::kInvalidArgument,
                  file + ": holds task " + std::to_string(part->task) + ", expected task " +
                      std::to_string(expect.task));
  }
  const size_t count = PartRow<Row>::Count(expect.rows);
  if (part->rows.size() != count) {
    return Status(StatusCode::kInvalidArgument,
                  file + ": " + std::to_string(part->rows.size()) + " " + PartRow<Row>::kKey +
                      ", task " + std::to_string(expect.task) + " has " + std::to_string(count));
  }
  for (size_t k = 0; k < part->rows.size(); ++k) {
    HANDDB_RETURN_IF_ERROR(PartRow<Row>::Check(part->rows[k], k, expect.rows, file));
  }
  return part;
}

template json PartToJson(const Part<ViewOutcome>&);
template json PartToJson(const Part<PhotoOutcome>&);
template Result<Part<ViewOutcome>> PartFromJson(const json&, const std::string&);
template Result<Part<PhotoOutcome>> PartFromJson(const json&, const std::string&);
template Status WritePart(const fs::path&, const Part<ViewOutcome>&);
template Status WritePart(const fs::path&, const Part<PhotoOutcome>&);
template Result<Part<ViewOutcome>> ReadPart(const fs::path&, const PartExpectation<ViewOutcome>&);
template Result<Part<PhotoOutcome>> ReadPart(const fs::path&, const PartExpectation<PhotoOutcome>&);

Status MergeParts(const fs::path& work_dir,
                  const EvaluationFingerprint& fingerprint,
                  std::span<const uint32_t> selected,
                  EvaluationReport* report) {
  report->views.clear();
  report->views.reserve(selected.size());
  const size_t num_criteria = report->criteria.size();
  int threads = 0;
  double wall_seconds = 0;
  HANDDB_RETURN_IF_ERROR(ReadAllParts<ViewOutcome>(
      work_dir,
      fingerprint,
      [&](uint32_t task) { return ExpectedPart(fingerprint, task, selected, num_criteria); },
      &report->views,
      &threads,
      &wall_seconds));
  if (threads > 0) report->threads = threads;
  FinishReport(report);
  report->wall_seconds = wall_seconds;
  return Status::Ok();
}

Status MergeParts(const fs::path& work_dir,
                  const EvaluationFingerprint& fingerprint,
                  const PhotoSet& photos,
                  PhotoReport* report) {
  report->outcomes.clear();
  report->outcomes.reserve(photos.photos.size());
  int threads = 0;
  double wall_seconds = 0;
  HANDDB_RETURN_IF_ERROR(ReadAllParts<PhotoOutcome>(
      work_dir,
      fingerprint,
      [&](uint32_t task) { return ExpectedPart(fingerprint, task, photos); },
      &report->outcomes,
      &threads,
      &wall_seconds));
  if (threads > 0) report->threads = threads;
  FinishPhotoReport(report);
  report->wall_seconds = wall_seconds;
  return Status::Ok();
}

// ---- Photo evaluations ------------------------------------------------------------------------

json PhotoScoringOptionsToJson(const PhotoEvaluationOptions& options, const json& query_options) {
  return {{"hand", std::string(HandName(options.hand))},
          {"top_k", kPhotoMatches},
          {"rank", options.max_per_shape == 1 ? "shapes" : "views"},
          {"query", query_options}};
}

Result<std::string> PhotoListChecksum(const PhotoSet& photos) {
  std::string list;
  for (const PhotoItem& p : photos.photos) {
    std::error_code ec;
    const uintmax_t size = fs::file_size(p.path, ec);
    if (ec) return Status(StatusCode::kIoError, p.path.string() + ": " + ec.message());
    list += p.relative + "\t" + std::to_string(size) + "\n";
  }
  return shard::ChecksumHex(shard::Checksum(list.data(), list.size()));
}

EvaluationFingerprint MakePhotoEvaluationFingerprint(const std::string& database_manifest_xxh3,
                                                     const std::string& photos_xxh3,
                                                     const std::string& keypoints_xxh3,
                                                     const json& scoring_options,
                                                     uint32_t num_tasks) {
  return FingerprintOf({{"database_manifest_xxh3", database_manifest_xxh3},
                        {"photos_xxh3", photos_xxh3},
                        {"keypoints_xxh3", keypoints_xxh3},
                        {"options", scoring_options},
                        {"tasks", num_tasks}});
}

Result<EvaluationFingerprint> ComputePhotoEvaluationFingerprint(const fs::path& db_dir,
                                                                const PhotoSet& photos,
                                                                const json& scoring_options,
                                                                uint32_t num_tasks) {
  auto manifest = shard::FileChecksum((db_dir / "manifest.json").string());
  if (!manifest.ok()) return manifest.status();
  auto list = PhotoListChecksum(photos);
  if (!list.ok()) return list.status();
  std::string keypoints;
  if (!photos.keypoints_file.empty()) {
    auto k = shard::FileChecksum(photos.keypoints_file.string());
    if (!k.ok()) return k.status();
    keypoints = shard::ChecksumHex(*k);
  }
  return MakePhotoEvaluationFingerprint(
      shard::ChecksumHex(*manifest), *list, keypoints, scoring_options, num_tasks);
}

}  // namespace handdb
