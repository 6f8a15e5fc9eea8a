#include "evaluate/parts.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <memory>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "evaluate/evaluate_testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// A test set of 9 views: database views at rank 1, views whose query shows another database view
// (a deeper search finds the rank), a truth no database shape is near, and a failed input.
struct Case {
  std::shared_ptr<const Database> db = testing::EvalDatabase();
  Searcher searcher{db};
  TestSet set;
  std::vector<std::pair<view_id_t, roll_id_t>> query_of;  // per test view: the edges it shows
  QueryPointsFn points;

  Case() {
    const std::pair<view_id_t, roll_id_t> truth[] = {
        {3, 0}, {17, 5}, {5, 2}, {29, 11}, {8, 0}, {9, 0}, {12, 4}, {21, 7}, {33, 1}};
    const std::pair<view_id_t, roll_id_t> query[] = {
        {3, 0}, {17, 5}, {30, 7}, {29, 11}, {8, 0}, {9, 0}, {12, 4}, {2, 3}, {33, 1}};
    for (uint32_t i = 0; i < 9; ++i) {
      TestView t = testing::ViewOf(*db, 100 + i, truth[i].first, truth[i].second, i % 3 == 0);
      if (i == 4) {
        for (auto& j : t.truth.joint_angles) j += 2.0f;  // unreachable
      }
      set.views.push_back(t);
      query_of.push_back(query[i]);
    }
    set.dir = "/tests/ts";
    set.file = "/tests/ts/testset.json";
    set.seed = 42;
    points = [this](const TestView& t) -> Result<TestQuery> {
      if (t.id == 105) return Status(StatusCode::kNoHand, "photo: no hand found");
      const auto [v, r] = query_of[t.id - 100];
      return TestQuery(testing::RolledView(*db, v, r));
    };
  }
};

EvaluationOptions FastOptions() {
  EvaluationOptions o;
  o.first_k = 10;
  o.num_threads = 1;
  o.progress = false;
  o.success_n = {1, 10, 100};
  return o;
}

// The report without the fields that depend on how the work ran (docs/cluster.md).
json WithoutRunSpecific(json doc) {
  for (const char* k : {"search_seconds",
                        "input_seconds",
                        "wall_seconds",
                        "queries_per_second",
                        "end_to_end_queries_per_second"}) {
    doc["timing"].erase(k);
  }
  for (auto& v : doc["views"]) {
    v.erase("input_seconds");
    v.erase("search_seconds");
  }
  return doc;
}

std::string WithoutSpeedLine(const std::string& text) {
  const size_t at = text.find("\nspeed ");
  return at == std::string::npos ? text : text.substr(0, at);
}

fs::path TempDir(const std::string& name) {
  const fs::path dir =
      fs::temp_directory_path() / ("handdb-eval-parts-" + std::to_string(getpid()) + "-" + name);
  fs::remove_all(dir);
  return dir;
}

// Runs task `task` of `num_tasks` as `handdb unit evaluate` does and writes its part.
void WriteTaskPart(const Case& c,
                   const EvaluationOptions& options,
                   const EvaluationFingerprint& fp,
                   uint32_t task,
                   uint32_t num_tasks,
                   const fs::path& work) {
  const auto selected = SelectTestViews(c.set, options);
  const auto slice = TaskSlice(selected, task, num_tasks);
  auto views = EvaluateViews(c.searcher, c.set, c.points, options, slice);
  ASSERT_TRUE(views.ok()) << views.status().ToString();
  EvaluationPart part;
  part.fingerprint = fp;
  part.task = task;
  part.num_tasks = num_tasks;
  part.threads = 1;
  part.started_at = 1000.0 + task;
  part.finished_at = 1010.0 + task;
  part.rows = std::move(*views);
  ASSERT_TRUE(WritePart(PartPath(work, task), part).ok());
}

TEST(EvalParts, TaskSlicesAreInterleavedAndCoverTheSelection) {
  const std::vector<uint32_t> selected = {0, 2, 4, 6, 8, 10, 12};
  EXPECT_EQ(TaskSlice(selected, 0, 3), (std::vector<uint32_t>{0, 6, 12}));
  EXPECT_EQ(TaskSlice(selected, 1, 3), (std::vector<uint32_t>{2, 8}));
  EXPECT_EQ(TaskSlice(selected, 2, 3), (std::vector<uint32_t>{4, 10}));
  EXPECT_TRUE(TaskSlice(selected, 9, 10).empty());
  EXPECT_EQ(PartPath("/w", 7), fs::path("/w/parts/part-00007.json"));
}

TEST(EvalParts, PartJsonRoundTripsExactly) {
  Case c;
  const EvaluationOptions options = FastOptions();
  auto views = EvaluateViews(c.searcher, c.set, c.points, options, SelectTestViews(c.set, options));
  ASSERT_TRUE(views.ok());
  EvaluationPart part;
  part.fingerprint = MakeEvaluationFingerprint("aa", "bb", QueryInput::kClean, options, 1);
  part.rows = std::move(*views);
  const json doc = PartToJson(part);
  ASSERT_TRUE(ValidateJson(doc, "evaluation_part.schema.json", "part").ok());
  auto back = PartFromJson<ViewOutcome>(json::parse(doc.dump()), "part");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(PartToJson(*back), doc);
  ASSERT_EQ(back->rows.size(), 9u);
  EXPECT_TRUE(std::isnan(back->rows[5].top1_keypoint_error));  // the failed input
  EXPECT_EQ(back->rows[5].error, "photo: no hand found");
  ASSERT_TRUE(back->rows[2].top1.has_value());
  EXPECT_EQ(back->rows[2].top1->distance, part.rows[2].top1->distance);  // bit for bit
  EXPECT_EQ(back->rows[2].top1_keypoint_error, part.rows[2].top1_keypoint_error);
  EXPECT_EQ(back->rows[2].floor_keypoint_error, part.rows[2].floor_keypoint_error);
  EXPECT_FALSE(std::isnan(back->rows[5].floor_keypoint_error));  // needs the truth only
  EXPECT_EQ(back->rows[2].wrist_to_middle_mcp_px, part.rows[2].wrist_to_middle_mcp_px);
  EXPECT_TRUE(std::isnan(back->rows[2].fitted_keypoint_error));
}

// The guarantee: a report merged from parts equals the report of one run, for any task count
// (including more tasks than views) and a stride.
TEST(EvalParts, MergedPartsEqualOneRun) {
  Case c;
  for (int stride : {1, 2}) {
    EvaluationOptions options = FastOptions();
    options.stride = stride;
    auto local = Evaluate(c.searcher, c.set, QueryInput::kClean, c.points, options);
    ASSERT_TRUE(local.ok());
    ASSERT_GT(local->deep_searches, 0) << "the case must cover deeper searches";
    ASSERT_EQ(local->failed_inputs, stride == 1 ? 1 : 0);
    const json local_json = ReportToJson(*local);
    for (uint32_t tasks : {1u, 2u, 4u, 12u}) {
      SCOPED_TRACE("stride " + std::to_string(stride) + ", tasks " + std::to_string(tasks));
      const fs::path work = TempDir("merge");
      const auto fp = MakeEvaluationFingerprint("db", "ts", QueryInput::kClean, options, tasks);
      // Tasks finish in any order.
      for (uint32_t t = tasks; t-- > 0;) WriteTaskPart(c, options, fp, t, tasks, work);
      EvaluationReport merged =
          StartReport(c.searcher.database(), c.set, QueryInput::kClean, options);
      Status s = MergeParts(work, fp, SelectTestViews(c.set, options), &merged);
      ASSERT_TRUE(s.ok()) << s.ToString();
      const json merged_json = ReportToJson(merged);
      EXPECT_TRUE(ValidateJson(merged_json, "evaluation.schema.json", "merged").ok());
      EXPECT_EQ(WithoutRunSpecific(merged_json).dump(2), WithoutRunSpecific(local_json).dump(2));
      EXPECT_EQ(WithoutSpeedLine(ReportToText(merged)), WithoutSpeedLine(ReportToText(*local)));
      EXPECT_EQ(merged.wall_seconds, 10.0 + (tasks - 1));  // first start to last finish
      fs::remove_all(work);
    }
  }
}

TEST(EvalParts, MissingAndMismatchedPartsAreNamed) {
  Case c;
  const EvaluationOptions options = FastOptions();
  const auto selected = SelectTestViews(c.set, options);
  const auto fp = MakeEvaluationFingerprint("db", "ts", QueryInput::kClean, options, 3);
  const fs::path work = TempDir("bad");
  for (uint32_t t = 0; t < 3; ++t) WriteTaskPart(c, options, fp, t, 3, work);
  auto merge = [&](const EvaluationFingerprint& f) {
    EvaluationReport r = StartReport(c.searcher.database(), c.set, QueryInput::kClean, options);
    return MergeParts(work, f, selected, &r);
  };
  ASSERT_TRUE(merge(fp).ok());
  const std::string part1 = PartPath(work, 1).string();

  // A part from another database / test set / options / split.
  auto expect_error = [&](const EvaluationFingerprint& f, const std::string& what) {
    const Status s = merge(f);
    ASSERT_FALSE(s.ok()) << what;
    EXPECT_NE(s.message().find(PartPath(work, 0).string()), std::string::npos) << s.message();
    EXPECT_NE(s.message().find(what), std::string::npos) << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos) << "one line";
  };
  expect_error(MakeEvaluationFingerprint("db2", "ts", QueryInput::kClean, options, 3),
               "another database");
  expect_error(MakeEvaluationFingerprint("db", "ts2", QueryInput::kClean, options, 3),
               "another test set");
  expect_error(MakeEvaluationFingerprint("db", "ts", QueryInput::kPhoto, options, 3),
               "--input clean");
  EvaluationOptions other = options;
  other.correctness.max_joint_distance_deg = 20;
  expect_error(MakeEvaluationFingerprint("db", "ts", QueryInput::kClean, other, 3),
               "max_joint_distance_deg: 15.0 vs 20.0");

  // A part holding another task's views.
  fs::copy_file(PartPath(work, 0), PartPath(work, 1), fs::copy_options::overwrite_existing);
  Status s = merge(fp);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), part1 + ": holds task 0, expected task 1");

  // A missing part.
  fs::remove(PartPath(work, 1));
  s = merge(fp);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
  EXPECT_EQ(s.message(), part1 + ": missing (task 1 of 3 has not written its part)");

  // A truncated part (a writer killed mid-way cannot leave one, but a copy can).
  ASSERT_TRUE(WriteFileAtomic(PartPath(work, 1), "{\"format\": \"handdb-evaluation-part\", ").ok());
  s = merge(fp);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message().rfind(part1, 0), 0u) << s.message();

  // A part whose views were edited away from its slice.
  WriteTaskPart(c, options, fp, 1, 3, work);
  auto doc = ReadJsonFile(PartPath(work, 1), "");
  ASSERT_TRUE(doc.ok());
  (*doc)["views"][0]["index"] = 0;
  ASSERT_TRUE(WriteJsonFileAtomic(PartPath(work, 1), *doc).ok());
  s = merge(fp);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), part1 + ": views[0] is test view 0, expected 1");
  fs::remove_all(work);
}

// ---- Photo evaluations ----

// Seven photos of a synthetic database, one of them a left hand, one without a hand, two annotated.
struct PhotoCase {
  std::shared_ptr<const Database> db = testing::EvalDatabase();
  Searcher searcher{db};
  PhotoSet set;
  PhotoQueryFn query_fn;
  struct Shown {
    view_id_t view;
    roll_id_t roll;
    bool mirrored;
  };
  std::map<std::string, Shown> shown = {{"shape0/a", {3, 0, false}},
                                        {"shape0/b", {5, 2, true}},
                                        {"shape1/c", {17, 5, false}},
                                        {"shape1/d", {30, 7, false}},  // a shape3 view
                                        {"shape2/e", {21, 1, false}},
                                        {"shape2/nohand", {0, 0, false}},
                                        {"shape3/f", {33, 11, true}}};

  PhotoCase() {
    set.dir = "/photos";
    for (const auto& [name, s] : shown) {
      PhotoItem item;
      item.relative = name;
      item.path = set.dir / name;
      item.expected_shape = name.substr(0, name.find('/'));
      set.photos.push_back(item);
    }
    for (size_t i : {1, 4}) {
      PhotoKeypoints kp;
      for (int k = 0; k < kNumKeypoints; ++k) {
        kp.px[k] = {static_cast<float>(200 + 7 * k), static_cast<float>(150 + 5 * (k % 4))};
        kp.visible[k] = k % 5 != 1;
      }
      kp.hand_size_px = HandSizePx(kp);
      set.photos[i].keypoints = kp;
    }
    set.keypoints_file = "kp.json";
    query_fn = [this](const PhotoItem& item) -> Result<PictureEvidence> {
      if (item.relative == "shape2/nohand") {
        return Status(StatusCode::kNoHand, "/photos/shape2/nohand: no hand found");
      }
      const Shown& s = shown.at(item.relative);
      return PictureEvidence(testing::PhotoQueryOf(*db, s.view, s.roll, s.mirrored, 250, 180, 0.8));
    };
  }
};

PhotoEvaluationOptions PhotoOptions() {
  PhotoEvaluationOptions o;
  o.hand = Hand::kEither;
  o.num_threads = 2;
  o.progress = false;
  return o;
}

json PhotoWithoutRunSpecific(json doc) {
  for (const char* k : {"search_seconds",
                        "input_seconds",
                        "wall_seconds",
                        "queries_per_second",
                        "end_to_end_queries_per_second"}) {
    doc["timing"].erase(k);
  }
  for (auto& p : doc["photos"]) {
    p.erase("input_seconds");
    p.erase("search_seconds");
  }
  return doc;
}

// Runs task `task` of `num_tasks` as `handdb unit evaluate-photos` does and writes its part.
void WritePhotoTaskPart(const PhotoCase& c,
                        const EvaluationFingerprint& fp,
                        uint32_t task,
                        uint32_t num_tasks,
                        const fs::path& work) {
  auto photos = ScorePhotos(c.searcher,
                            c.set,
                            c.query_fn,
                            PhotoOptions(),
                            TaskSlice(c.set.photos.size(), task, num_tasks));
  ASSERT_TRUE(photos.ok()) << photos.status().ToString();
  PhotoEvaluationPart part;
  part.fingerprint = fp;
  part.task = task;
  part.num_tasks = num_tasks;
  part.threads = 2;
  part.started_at = 500.0 + task;
  part.finished_at = 520.0 + task;
  part.rows = std::move(*photos);
  ASSERT_TRUE(WritePart(PartPath(work, task), part).ok());
}

EvaluationFingerprint PhotoFingerprint(uint32_t tasks,
                                       const std::string& photos = "photos",
                                       const std::string& keypoints = "kp",
                                       Hand hand = Hand::kEither) {
  PhotoEvaluationOptions o = PhotoOptions();
  o.hand = hand;
  return MakePhotoEvaluationFingerprint(
      "db", photos, keypoints, PhotoScoringOptionsToJson(o, {{"input", "auto"}}), tasks);
}

// The guarantee for photos: a report merged from parts equals the report of one run.
TEST(EvalParts, MergedPhotoPartsEqualOneRun) {
  PhotoCase c;
  auto local = EvaluatePhotos(c.searcher, c.set, c.query_fn, PhotoOptions());
  ASSERT_TRUE(local.ok());
  ASSERT_EQ(local->failed_inputs, 1);
  ASSERT_EQ(local->top1_left, 2) << "the case must cover left hands";
  ASSERT_EQ(local->annotated_photos, 2) << "and annotations";
  const json local_json = PhotoReportToJson(*local);
  for (uint32_t tasks : {1u, 2u, 3u, 7u}) {
    SCOPED_TRACE("tasks " + std::to_string(tasks));
    const fs::path work = TempDir("photo-merge");
    const auto fp = PhotoFingerprint(tasks);
    for (uint32_t t = tasks; t-- > 0;) WritePhotoTaskPart(c, fp, t, tasks, work);
    PhotoReport merged = StartPhotoReport(c.searcher.database(), c.set, PhotoOptions());
    Status s = MergeParts(work, fp, c.set, &merged);
    ASSERT_TRUE(s.ok()) << s.ToString();
    const json merged_json = PhotoReportToJson(merged);
    EXPECT_TRUE(ValidateJson(merged_json, "photo_evaluation.schema.json", "merged").ok());
    EXPECT_EQ(PhotoWithoutRunSpecific(merged_json).dump(2),
              PhotoWithoutRunSpecific(local_json).dump(2));
    EXPECT_EQ(WithoutSpeedLine(PhotoReportToText(merged)),
              WithoutSpeedLine(PhotoReportToText(*local)));
    EXPECT_EQ(merged.wall_seconds, 20.0 + (tasks - 1));
    fs::remove_all(work);
  }
}

TEST(EvalParts, PhotoPartsOfAnotherEvaluationAreNamed) {
  PhotoCase c;
  const auto fp = PhotoFingerprint(3);
  const fs::path work = TempDir("photo-bad");
  for (uint32_t t = 0; t < 3; ++t) WritePhotoTaskPart(c, fp, t, 3, work);
  auto merge = [&](const EvaluationFingerprint& f) {
    PhotoReport r = StartPhotoReport(c.searcher.database(), c.set, PhotoOptions());
    return MergeParts(work, f, c.set, &r);
  };
  ASSERT_TRUE(merge(fp).ok());
  const std::string part0 = PartPath(work, 0).string();
  auto expect_error = [&](const EvaluationFingerprint& f, const std::string& what) {
    const Status s = merge(f);
    ASSERT_FALSE(s.ok()) << what;
    EXPECT_EQ(s.message().rfind(part0 + ": a part of another evaluation: ", 0), 0u) << s.message();
    EXPECT_NE(s.message().find(what), std::string::npos) << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos) << "one line";
  };
  expect_error(PhotoFingerprint(3, "photos2"),
               "made from other photos (photo names and sizes xxh3 photos, this one's is photos2)");
  expect_error(PhotoFingerprint(3, "photos", ""),
               "made with another --keypoints file (xxh3 kp, this one's is none)");
  expect_error(PhotoFingerprint(3, "photos", "kp", Hand::kRight),
               "made with other evaluation options (hand: \"either\" vs \"right\")");
  expect_error(PhotoFingerprint(2), "made for a split into 3 tasks, not 2");

  // A part holding another slice's photos, and a missing one.
  const std::string part1 = PartPath(work, 1).string();
  auto doc = ReadJsonFile(PartPath(work, 1), "");
  ASSERT_TRUE(doc.ok());
  (*doc)["photos"][0]["photo"] = "shape0/a";
  ASSERT_TRUE(WriteJsonFileAtomic(PartPath(work, 1), *doc).ok());
  Status s = merge(fp);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), part1 + ": photos[0] is shape0/a, expected shape0/b");
  fs::remove(PartPath(work, 1));
  s = merge(fp);
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
  EXPECT_EQ(s.message(), part1 + ": missing (task 1 of 3 has not written its part)");
  fs::remove_all(work);
}

TEST(EvalParts, PhotoListChecksumFollowsNamesAndSizes) {
  const fs::path dir = TempDir("photo-list");
  fs::create_directories(dir / "a");
  PhotoSet set;
  set.dir = dir;
  for (const char* name : {"a/1.jpg", "a/2.jpg"}) {
    std::ofstream(dir / name) << "12345";
    set.photos.push_back({dir / name, name, "a", std::nullopt});
  }
  auto first = PhotoListChecksum(set);
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(*PhotoListChecksum(set), *first);  // deterministic
  std::ofstream(dir / "a/2.jpg") << "123456";  // another size
  EXPECT_NE(*PhotoListChecksum(set), *first);
  set.photos.pop_back();
  EXPECT_NE(*PhotoListChecksum(set), *first);
  set.photos.push_back({dir / "a/9.jpg", "a/9.jpg", "a", std::nullopt});
  auto missing = PhotoListChecksum(set);
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("9.jpg"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace handdb
