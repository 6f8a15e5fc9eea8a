#include "evaluate/photos.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "base/json_schema.h"
#include "base/testing.h"
#include "evaluate/evaluate_testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

PhotoOutcome Outcome(const std::string& photo, std::vector<std::string> shapes) {
  PhotoOutcome o;
  o.photo = photo;
  o.expected_shape = photo.substr(0, photo.find('/'));
  o.match_shapes = std::move(shapes);
  o.match_distances.assign(o.match_shapes.size(), 1.0);
  o.match_hands.assign(o.match_shapes.size(), Hand::kRight);
  o.search_seconds = 0.5;
  o.input_seconds = 0.25;
  return o;
}

// 100 virtual views: 50 of shape a, 30 of b, 20 of c; five photos with known ranks (views
// ranked: a shape may fill several ranks).
PhotoReport KnownReport() {
  PhotoReport r;
  r.max_per_shape = 0;
  r.database_views = 25;
  r.database_rolls = 4;
  r.database_virtual_views = 100;
  r.threads = 2;
  r.virtual_views_per_shape = {{"a", 50}, {"b", 30}, {"c", 20}};
  r.outcomes.push_back(Outcome("b/2", std::vector<std::string>(10, "a")));  // miss
  r.outcomes.push_back(Outcome("a/1", {"a", "b"}));                         // rank 1
  r.outcomes.push_back(Outcome("a/2", {"b", "b", "a"}));                    // rank 3
  r.outcomes.back().match_hands[0] = Hand::kLeft;  // its top-1 matched the mirrored photo
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
  EXPECT_EQ(r.top1_left, 1);  // failed inputs have no top-1 hand
  EXPECT_EQ(r.top1_right, 3);
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

// Shapes ranked: the chance of the right shape among the first k distinct shapes of a random
// ordering, against every arrangement of a small multiset of views counted by hand.
TEST(PhotoEvaluation, ShapeChanceIsTheFirstDistinctShapesOfARandomOrdering) {
  const std::map<std::string, uint64_t> sizes = {{"a", 1}, {"b", 2}, {"c", 3}, {"d", 1}};
  std::vector<char> views = {'a', 'b', 'b', 'c', 'c', 'c', 'd'};
  std::map<char, std::array<int64_t, 5>> among;  // shape -> arrangements with it in the first k
  int64_t arrangements = 0;
  do {
    ++arrangements;
    std::string first;
    for (char v : views) {
      if (first.find(v) == std::string::npos) first += v;
    }
    for (size_t k = 1; k <= 4; ++k) {
      for (size_t i = 0; i < k; ++i) ++among[first[i]][k];
    }
  } while (std::next_permutation(views.begin(), views.end()));
  for (const auto& [name, n] : sizes) {
    for (int k = 1; k <= 4; ++k) {
      SCOPED_TRACE(name + " k=" + std::to_string(k));
      const double expected =
          static_cast<double>(among[name[0]][k]) / static_cast<double>(arrangements);
      EXPECT_NEAR(ChanceOfShapeAmongFirstK(sizes, name, k), expected, 1e-5);
    }
  }
  // k = 1 is the share of the shape's views; equal sizes give k / S; unknown shapes never come.
  EXPECT_NEAR(ChanceOfShapeAmongFirstK({{"a", 50}, {"b", 30}, {"c", 20}}, "b", 1), 0.3, 1e-5);
  std::map<std::string, uint64_t> equal;
  for (int s = 0; s < 26; ++s) equal["s" + std::to_string(s)] = 4128;
  EXPECT_NEAR(ChanceOfShapeAmongFirstK(equal, "s3", 5), 5.0 / 26, 1e-5);
  EXPECT_EQ(ChanceOfShapeAmongFirstK(equal, "zzz", 5), 0.0);
  EXPECT_EQ(ChanceOfShapeAmongFirstK(equal, "s3", 26), 1.0);

  PhotoReport r = KnownReport();
  r.max_per_shape = 1;
  FinishPhotoReport(&r);
  EXPECT_NEAR(r.chance[0], (3 * 0.5 + 2 * 0.3) / 5, 1e-5);
  EXPECT_EQ(r.chance[1], 1.0);  // three shapes: every one is among the first 5
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

// Annotated outcomes with hand-made distances: hand size 100 px, keypoints 0..9 at 2 px, 10..19 at
// 8 px and 20 hidden (top-1); the best of the top 10 is 1 px everywhere. One more annotated photo
// failed (its 15 visible keypoints count as missed in PCK) and one is not annotated.
PhotoReport AnnotatedReport() {
  PhotoReport r;
  r.database_views = 10;
  r.database_rolls = 1;
  r.database_virtual_views = 10;
  r.threads = 1;
  r.virtual_views_per_shape = {{"a", 10}};
  r.keypoints_file = "kp.json";
  PhotoKeypointResult k;
  k.hand_size_px = 100;
  for (int i = 0; i < kNumKeypoints; ++i) {
    k.top1_px[i] = i < 10 ? 2 : 8;
    k.best10_px[i] = 1;
  }
  k.top1_px[20] = k.best10_px[20] = std::nan("");
  k.best10_rank = 4;
  PhotoOutcome good = Outcome("a/good", {"a"});
  good.annotated_keypoints = 20;
  good.keypoints = k;
  PhotoKeypointResult twice = k;  // the same errors on a hand twice as large
  twice.hand_size_px = 200;
  PhotoOutcome big = Outcome("a/big", {"a"});
  big.annotated_keypoints = 20;
  big.keypoints = twice;
  PhotoOutcome failed = Outcome("a/failed", {});
  failed.error = "a/failed: no hand found";
  failed.annotated_keypoints = 15;
  r.outcomes = {good, big, failed, Outcome("a/plain", {"a"})};
  FinishPhotoReport(&r);
  return r;
}

TEST(PhotoEvaluation, KeypointErrorAndPckOverAnnotatedPhotos) {
  const PhotoReport r = AnnotatedReport();
  EXPECT_EQ(r.annotated_photos, 3);
  EXPECT_EQ(r.annotated_failed, 1);
  // Per photo: mean of 10 x 2 px and 10 x 8 px = 5 px over 100 px and over 200 px.
  EXPECT_EQ(r.top1_keypoints.error.count, 2);
  EXPECT_DOUBLE_EQ(r.top1_keypoints.error.mean, (0.05 + 0.025) / 2);
  EXPECT_DOUBLE_EQ(r.top1_keypoints.error.median, (0.05 + 0.025) / 2);
  EXPECT_DOUBLE_EQ(r.best10_keypoints.error.mean, (0.01 + 0.005) / 2);
  // PCK over 20 + 20 + 15 = 55 visible keypoints. Thresholds 0.05, 0.1, 0.2 hand sizes: 5, 10,
  // 20 px on the first photo (2 px: 10 within 5; 8 px: 20 within 10) and 10, 20, 40 px on the
  // second (all 20 within 10); the failed photo's 15 never count.
  ASSERT_EQ(kPckThresholds.size(), 3u);
  EXPECT_DOUBLE_EQ(r.top1_keypoints.pck[0], 30.0 / 55);
  EXPECT_DOUBLE_EQ(r.top1_keypoints.pck[1], 40.0 / 55);
  EXPECT_DOUBLE_EQ(r.top1_keypoints.pck[2], 40.0 / 55);
  EXPECT_DOUBLE_EQ(r.best10_keypoints.pck[0], 40.0 / 55);

  const nlohmann::json doc = PhotoReportToJson(r);
  const Status valid = ValidateJson(doc, "photo_evaluation.schema.json", "report");
  EXPECT_TRUE(valid.ok()) << valid.message();
  EXPECT_EQ(doc["keypoints"]["annotated_photos"], 3);
  EXPECT_EQ(doc["keypoints"]["top1"]["pck"][1]["threshold"], 0.1);
  const std::string text = PhotoReportToText(r);
  EXPECT_NE(text.find("2D keypoints (kp.json): 3 of 4 photos annotated"), std::string::npos)
      << text;
  EXPECT_NE(text.find("1 annotated photos without a usable query"), std::string::npos) << text;
  // Without --keypoints the report says nothing of keypoints.
  EXPECT_TRUE(PhotoReportToJson(KnownReport())["keypoints"].is_null());
  EXPECT_EQ(PhotoReportToText(KnownReport()).find("2D keypoints"), std::string::npos);
}

TEST(PhotoEvaluation, OutcomeJsonRoundTripsExactly) {
  PhotoReport r = AnnotatedReport();
  PhotoOutcome o = r.outcomes[2];  // sorted: a/big, a/failed, a/good, a/plain
  ASSERT_EQ(o.photo, "a/good");
  o.match_hands = {Hand::kLeft};
  o.top1_view = 17;
  o.top1_roll = 5;
  for (int k = 0; k < kNumKeypoints; ++k) {
    o.top1_keypoints_px.push_back({0.1f * static_cast<float>(k) + 1e-3f, 1.0f / 3.0f});
  }
  o.input_seconds = 0.123456789;
  const nlohmann::json j = o.ToJson();
  EXPECT_TRUE(
      ValidateJsonWithSchema(j, {{"$ref", "photo_evaluation.schema.json#/$defs/photo"}}, "outcome")
          .ok());
  EXPECT_EQ(j["top1"]["hand"], "left");
  EXPECT_TRUE(j["keypoints"]["top1_distances_px"][20].is_null());
  auto back = PhotoOutcome::FromJson(nlohmann::json::parse(j.dump()), "outcome");
  ASSERT_TRUE(back.ok()) << back.status().message();
  EXPECT_EQ(back->ToJson(), j);
  EXPECT_EQ(back->top1_keypoints_px[7].x, o.top1_keypoints_px[7].x);  // bit for bit
  EXPECT_EQ(back->input_seconds, o.input_seconds);
  EXPECT_TRUE(std::isnan(back->keypoints->top1_px[20]));
}

TEST(PhotoEvaluation, AnnotationsMustNamePhotosOfTheDirectory) {
  const fs::path dir = testing::TempDir("photo_annotations");
  fs::create_directories(dir / "a");
  fs::create_directories(dir / "zzz");
  for (const char* f : {"a/1.jpg", "a/2.png", "a/notes.txt", "zzz/3.jpg"}) {
    std::ofstream(dir / f) << "x";
  }
  auto set = ListPhotoFolders(dir, std::vector<std::string>{"a"}, /*skip_unknown=*/true);
  ASSERT_TRUE(set.ok());
  PhotoKeypointFile file;
  file.path = "kp.json";
  PhotoKeypoints kp;
  kp.visible.fill(true);
  file.images["a/2.png"] = kp;
  file.images["zzz/3.jpg"] = kp;  // a photo of a skipped folder: not counted, no error
  ASSERT_TRUE(AttachPhotoKeypoints(file, &*set).ok());
  EXPECT_EQ(set->keypoints_file, "kp.json");
  EXPECT_FALSE(set->photos[0].keypoints.has_value());
  EXPECT_TRUE(set->photos[1].keypoints.has_value());

  file.images["a/9.jpg"] = kp;
  Status s = AttachPhotoKeypoints(file, &*set);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(),
            "kp.json: images[\"a/9.jpg\"]: no such image in " + dir.string() +
                " (keys are photo paths relative to it: <shape folder>/<file>)");
  file.images.erase("a/9.jpg");
  file.images["a/notes.txt"] = kp;
  s = AttachPhotoKeypoints(file, &*set);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("images[\"a/notes.txt\"]: not one of the photos evaluated"),
            std::string::npos)
      << s.message();
  fs::remove_all(dir);
}

// The real search on a synthetic database: a photo's query is database view (v, r), or its mirror
// image (a left hand), placed in a 640 x 480 picture at 2 picture px per normalised px.
class ScorePhotosTest : public ::testing::Test {
 protected:
  static constexpr double kScale = 0.5;  // normalised px per picture px
  static constexpr double kCentreX = 300, kCentreY = 220;

  std::shared_ptr<const Database> db_ = testing::EvalDatabase();
  Searcher searcher_{db_};

  struct Shown {
    view_id_t view;
    roll_id_t roll;
    bool mirrored;
  };
  std::map<std::string, Shown> shown_;

  PhotoSet Photos() {
    PhotoSet set;
    set.dir = "/photos";
    shown_ = {{"shape0/v3", {3, 2, false}},
              {"shape1/v17-left", {17, 7, true}},
              {"shape2/v25", {25, 0, false}}};
    for (const auto& [name, s] : shown_) {
      PhotoItem item;
      item.relative = name;
      item.path = set.dir / name;
      item.expected_shape = name.substr(0, name.find('/'));
      set.photos.push_back(item);
    }
    return set;
  }

  PhotoQueryFn QueryFn() {
    return [this](const PhotoItem& item) -> Result<PictureEvidence> {
      const Shown& s = shown_.at(item.relative);
      return PictureEvidence(
          testing::PhotoQueryOf(*db_, s.view, s.roll, s.mirrored, kCentreX, kCentreY, kScale));
    };
  }

  // Where the photo shows view (v, r)'s keypoints, in picture px.
  std::vector<Point2f> TrueKeypointsPx(const Shown& s) const {
    const ViewLabel label = RollLabel(db_->label(s.view), RollAngle(s.roll, db_->num_rolls()));
    std::vector<Point2f> px;
    for (const auto& k : label.keypoints) {
      const double x = s.mirrored ? -k[0] : k[0];
      px.push_back({static_cast<float>(x / kScale + kCentreX),
                    static_cast<float>(k[1] / kScale + kCentreY)});
    }
    return px;
  }

  static PhotoEvaluationOptions Options(Hand hand) {
    PhotoEvaluationOptions o;
    o.hand = hand;
    o.num_threads = 2;
    o.progress = false;
    return o;
  }
};

// Views ranked: the k nearest (view, roll, hand) triples, several of one shape; the top-1 is the
// same either way.
TEST_F(ScorePhotosTest, RankingViewsKeepsEveryNearViewOfAShape) {
  PhotoSet set = Photos();
  PhotoEvaluationOptions options = Options(Hand::kEither);
  options.max_per_shape = 0;
  auto views = EvaluatePhotos(searcher_, set, QueryFn(), options);
  auto shapes = EvaluatePhotos(searcher_, set, QueryFn(), Options(Hand::kEither));
  ASSERT_TRUE(views.ok() && shapes.ok());
  EXPECT_EQ(views->max_per_shape, 0);
  EXPECT_EQ(PhotoReportToJson(*views)["search"]["rank"], "views");
  EXPECT_EQ(PhotoReportToJson(*shapes)["search"]["rank"], "shapes");
  for (size_t i = 0; i < views->outcomes.size(); ++i) {
    const PhotoOutcome& v = views->outcomes[i];
    ASSERT_EQ(v.match_shapes.size(), static_cast<size_t>(kPhotoMatches));
    EXPECT_LT(std::set<std::string>(v.match_shapes.begin(), v.match_shapes.end()).size(),
              v.match_shapes.size());
    EXPECT_EQ(v.top1_view, shapes->outcomes[i].top1_view);
  }
  options.max_per_shape = 2;
  EXPECT_FALSE(options.Check());
}

TEST_F(ScorePhotosTest, EitherHandFindsTheMirroredPhotoAsALeftHandAndPlacesItsKeypoints) {
  PhotoSet set = Photos();
  auto report = EvaluatePhotos(searcher_, set, QueryFn(), Options(Hand::kEither));
  ASSERT_TRUE(report.ok()) << report.status().message();
  EXPECT_EQ(report->hand, Hand::kEither);
  EXPECT_EQ(report->hits[0], 3);
  EXPECT_EQ(report->top1_left, 1);
  EXPECT_EQ(report->top1_right, 2);
  for (const PhotoOutcome& o : report->outcomes) {
    SCOPED_TRACE(o.photo);
    const Shown& s = shown_.at(o.photo);
    EXPECT_EQ(o.top1_view, s.view);
    EXPECT_EQ(o.top1_roll, s.roll);
    // Shapes ranked (the default): one match per shape, the database's 4 shapes.
    ASSERT_EQ(o.match_hands.size(), 4u);
    EXPECT_EQ(std::set<std::string>(o.match_shapes.begin(), o.match_shapes.end()).size(), 4u);
    EXPECT_EQ(o.match_hands[0], s.mirrored ? Hand::kLeft : Hand::kRight);
    // The top-1 keypoints land where the photo shows them: the left hand's mirrored back.
    const auto truth = TrueKeypointsPx(s);
    ASSERT_EQ(o.top1_keypoints_px.size(), truth.size());
    for (size_t k = 0; k < truth.size(); ++k) {
      EXPECT_NEAR(o.top1_keypoints_px[k].x, truth[k].x, 1e-3) << k;
      EXPECT_NEAR(o.top1_keypoints_px[k].y, truth[k].y, 1e-3) << k;
    }
  }
  const nlohmann::json doc = PhotoReportToJson(*report);
  EXPECT_TRUE(ValidateJson(doc, "photo_evaluation.schema.json", "report").ok());
  EXPECT_EQ(doc["search"]["hand"], "either");
  EXPECT_EQ(doc["top1_hands"]["left"], 1);
}

TEST_F(ScorePhotosTest, RightHandOnlySearchesThePhotoAsItIs) {
  PhotoSet set = Photos();
  auto report = EvaluatePhotos(searcher_, set, QueryFn(), Options(Hand::kRight));
  ASSERT_TRUE(report.ok());
  EXPECT_EQ(report->top1_left, 0);
  for (const PhotoOutcome& o : report->outcomes) {
    for (Hand h : o.match_hands) EXPECT_EQ(h, Hand::kRight);
    if (shown_.at(o.photo).mirrored) {
      EXPECT_GT(o.match_distances[0], 1.0);  // no right-hand view is the mirror image
    } else {
      EXPECT_LT(o.match_distances[0], 0.1);
    }
  }
  // --hand left mirrors every photo: only the left hand's photo is found exactly.
  auto left = EvaluatePhotos(searcher_, set, QueryFn(), Options(Hand::kLeft));
  ASSERT_TRUE(left.ok());
  EXPECT_EQ(left->top1_left, 3);
  for (const PhotoOutcome& o : left->outcomes) {
    EXPECT_EQ(o.match_distances[0] < 0.1, shown_.at(o.photo).mirrored) << o.photo;
  }
}

TEST_F(ScorePhotosTest, AnnotatedPhotosGetTheKeypointErrorOfTopOneAndBestOfTen) {
  PhotoSet set = Photos();
  // The left hand's photo annotated 3 px right and 4 px below the truth, the wrist hidden; the
  // first photo annotated exactly.
  PhotoKeypoints shifted;
  const auto truth = TrueKeypointsPx(shown_.at("shape1/v17-left"));
  for (int k = 0; k < kNumKeypoints; ++k) {
    shifted.px[k] = {truth[k].x + 3, truth[k].y + 4};
    shifted.visible[k] = k != 0;
  }
  shifted.hand_size_px = HandSizePx(shifted);
  PhotoKeypoints exact;
  const auto truth0 = TrueKeypointsPx(shown_.at("shape0/v3"));
  std::copy(truth0.begin(), truth0.end(), exact.px.begin());
  exact.visible.fill(true);
  exact.hand_size_px = HandSizePx(exact);
  set.photos[0].keypoints = exact;    // shape0/v3
  set.photos[1].keypoints = shifted;  // shape1/v17-left
  set.keypoints_file = "kp.json";
  auto report = EvaluatePhotos(searcher_, set, QueryFn(), Options(Hand::kEither));
  ASSERT_TRUE(report.ok());
  EXPECT_EQ(report->annotated_photos, 2);
  const PhotoOutcome& left = report->outcomes[1];
  ASSERT_EQ(left.photo, "shape1/v17-left");
  EXPECT_EQ(left.annotated_keypoints, 20);
  ASSERT_TRUE(left.keypoints.has_value());
  EXPECT_TRUE(std::isnan(left.keypoints->top1_px[0]));
  for (int k = 1; k < kNumKeypoints; ++k) EXPECT_NEAR(left.keypoints->top1_px[k], 5.0, 1e-3);
  EXPECT_NEAR(left.keypoints->top1_error(), 5.0 / shifted.hand_size_px, 1e-5);
  EXPECT_EQ(left.keypoints->best10_rank, 1);
  EXPECT_NEAR(report->outcomes[0].keypoints->top1_error(), 0.0, 1e-5);
  EXPECT_FALSE(report->outcomes[2].keypoints.has_value());  // not annotated
  EXPECT_EQ(report->top1_keypoints.error.count, 2);
  EXPECT_NEAR(report->top1_keypoints.error.mean, 2.5 / shifted.hand_size_px, 1e-5);
  // 5 px is within 0.05 hand sizes (the hand spans a few hundred px): PCK 100% everywhere.
  ASSERT_GT(0.05 * shifted.hand_size_px, 5.0);
  EXPECT_DOUBLE_EQ(report->top1_keypoints.pck[0], 1.0);
}

}  // namespace
}  // namespace handdb
