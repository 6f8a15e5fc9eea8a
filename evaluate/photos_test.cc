#include "evaluate/photos.h"

#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "base/json_schema.h"
#include "base/testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

PhotoOutcome Outcome(const std::string& photo, std::vector<std::string> shapes) {
  PhotoOutcome o;
  o.photo = photo;
  o.expected_shape = photo.substr(0, photo.find('/'));
  o.match_shapes = std::move(shapes);
  o.match_distances.assign(o.match_shapes.size(), 1.0);
  o.search_seconds = 0.5;
  o.input_seconds = 0.25;
  return o;
}

// 100 virtual views: 50 of shape a, 30 of b, 20 of c; five photos with known ranks.
PhotoReport KnownReport() {
  PhotoReport r;
  r.database_views = 25;
  r.database_rolls = 4;
  r.database_virtual_views = 100;
  r.threads = 2;
  r.virtual_views_per_shape = {{"a", 50}, {"b", 30}, {"c", 20}};
  r.outcomes.push_back(Outcome("b/2", std::vector<std::string>(10, "a")));  // miss
  r.outcomes.push_back(Outcome("a/1", {"a", "b"}));                         // rank 1
  r.outcomes.push_back(Outcome("a/2", {"b", "b", "a"}));                    // rank 3
  PhotoOutcome failed = Outcome("a/3", {});
  failed.error = "a/3: no hand found";
  r.outcomes.push_back(failed);
  r.outcomes.push_back(Outcome("b/1", {"c", "c", "c", "c", "c", "c", "b"}));  // rank 7
  FinishPhotoReport(&r);
  return r;
}

TEST(PhotoEvaluation, ShapeRankIsTheFirstMatchOfTheExpectedShape) {
  EXPECT_EQ(ShapeRank(Outcome("a/x", {"b", "a", "a"})), 2);
  EXPECT_EQ(ShapeRank(Outcome("a/x", {"b", "c"})), 0);
  PhotoOutcome failed = Outcome("a/x", {"a"});
  failed.error = "no hand";
  EXPECT_EQ(ShapeRank(failed), 0);
}

TEST(PhotoEvaluation, AccuracyAtKCountsFailedInputsAsMisses) {
  const PhotoReport r = KnownReport();
  ASSERT_EQ(r.ks, (std::vector<int>{1, 5, 10}));
  EXPECT_EQ(r.hits, (std::vector<int64_t>{1, 2, 3}));
  EXPECT_DOUBLE_EQ(r.accuracy[0], 0.2);
  EXPECT_DOUBLE_EQ(r.accuracy[1], 0.4);
  EXPECT_DOUBLE_EQ(r.accuracy[2], 0.6);
  EXPECT_EQ(r.failed_inputs, 1);
  EXPECT_EQ(r.outcomes.front().photo, "a/1");  // sorted by name
  // Four searched photos at 0.5 s, five inputs at 0.25 s.
  EXPECT_DOUBLE_EQ(r.queries_per_second, 4 / 2.5);
  EXPECT_DOUBLE_EQ(r.end_to_end_queries_per_second, 5 / 3.75);
}

TEST(PhotoEvaluation, ChanceIsTheHypergeometricBaselineAveragedOverPhotos) {
  const PhotoReport r = KnownReport();
  // k = 1: the share of the right shape, three photos of a (0.5), two of b (0.3).
  EXPECT_NEAR(r.chance[0], (3 * 0.5 + 2 * 0.3) / 5, 1e-12);
  // k = 5: 1 - C(n - m, 5) / C(n, 5).
  auto none = [](double n, double m) {
    double p = 1;
    for (int i = 0; i < 5; ++i) p *= (n - m - i) / (n - i);
    return p;
  };
  EXPECT_NEAR(r.chance[1], (3 * (1 - none(100, 50)) + 2 * (1 - none(100, 30))) / 5, 1e-12);
  EXPECT_GT(r.chance[2], r.chance[1]);
}

TEST(PhotoEvaluation, PerShapeTableAndConfusion) {
  const PhotoReport r = KnownReport();
  ASSERT_EQ(r.shapes.size(), 2u);
  EXPECT_EQ(r.shapes[0].shape, "a");
  EXPECT_EQ(r.shapes[0].photos, 3);
  EXPECT_EQ(r.shapes[0].hits, (std::vector<int64_t>{1, 2, 2}));
  // a/2 -> b and a/3 -> no hand: a tie, broken alphabetically.
  EXPECT_EQ(r.shapes[0].top_wrong, "b");
  EXPECT_EQ(r.shapes[0].top_wrong_count, 1);
  EXPECT_EQ(r.shapes[1].shape, "b");
  EXPECT_EQ(r.shapes[1].hits, (std::vector<int64_t>{0, 0, 1}));
  EXPECT_EQ(r.shapes[1].top_wrong, "a");
  EXPECT_EQ(r.confusion_rows, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(r.confusion_cols, (std::vector<std::string>{"a", "b", "c", kNoHandLabel}));
  EXPECT_EQ(r.confusion[0], (std::vector<int64_t>{1, 1, 0, 1}));
  EXPECT_EQ(r.confusion[1], (std::vector<int64_t>{1, 0, 1, 0}));
}

TEST(PhotoEvaluation, JsonFollowsItsSchemaAndTextListsFailures) {
  const PhotoReport r = KnownReport();
  const Status valid = ValidateJson(PhotoReportToJson(r), "photo_evaluation.schema.json", "report");
  EXPECT_TRUE(valid.ok()) << valid.message();
  nlohmann::json broken = PhotoReportToJson(r);
  broken["accuracy"][0]["rate"] = 1.5;
  EXPECT_FALSE(ValidateJson(broken, "photo_evaluation.schema.json", "report").ok());
  const std::string text = PhotoReportToText(r);
  EXPECT_NE(text.find("a/3: no hand found"), std::string::npos);
  EXPECT_NE(text.find("20.0%"), std::string::npos);
}

TEST(PhotoEvaluation, ConfusionPngHasACellPerPair) {
  const fs::path dir = testing::TempDir("photo_confusion");
  const PhotoReport r = KnownReport();
  ASSERT_TRUE(WriteConfusionPng(dir / "c.png", r).ok());
  const cv::Mat image = cv::imread((dir / "c.png").string());
  ASSERT_FALSE(image.empty());
  EXPECT_GT(image.cols, 4 * 34);
  EXPECT_GT(image.rows, 2 * 34);
  fs::remove_all(dir);
}

TEST(PhotoEvaluation, FoldersAreShapesOfTheDatabase) {
  const fs::path dir = testing::TempDir("photo_folders");
  fs::create_directories(dir / "asl-1");
  fs::create_directories(dir / "asl-0");
  for (const char* f :
       {"asl-0/b.JPG", "asl-0/a.png", "asl-0/notes.md", "asl-1/c.jpeg", "LICENSE"}) {
    std::ofstream(dir / f) << "x";
  }
  const std::vector<std::string> shapes = {"asl-0", "asl-1", "fist"};
  auto set = ListPhotoFolders(dir, shapes, false);
  ASSERT_TRUE(set.ok()) << set.status().message();
  ASSERT_EQ(set->photos.size(), 3u);
  EXPECT_EQ(set->photos[0].relative, "asl-0/a.png");
  EXPECT_EQ(set->photos[1].relative, "asl-0/b.JPG");
  EXPECT_EQ(set->photos[2].expected_shape, "asl-1");

  fs::create_directories(dir / "thumbs-up");
  std::ofstream(dir / "thumbs-up" / "d.jpg") << "x";
  auto bad = ListPhotoFolders(dir, shapes, false);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("thumbs-up"), std::string::npos);
  auto skipped = ListPhotoFolders(dir, shapes, true);
  ASSERT_TRUE(skipped.ok());
  EXPECT_EQ(skipped->photos.size(), 3u);
  EXPECT_EQ(skipped->skipped_folders, (std::vector<std::string>{"thumbs-up"}));

  EXPECT_EQ(ListPhotoFolders(dir / "missing", shapes, false).status().code(),
            StatusCode::kNotFound);
  const fs::path empty = testing::TempDir("photo_folders_empty");
  EXPECT_EQ(ListPhotoFolders(empty, shapes, false).status().code(), StatusCode::kInvalidArgument);
  fs::remove_all(dir);
  fs::remove_all(empty);
}

}  // namespace
}  // namespace handdb
