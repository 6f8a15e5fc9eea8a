// `handdb evaluate DB --photos DIR` end to end: a synthetic database (ShardWriter +
// WriteManifest, shapes "alpha" and "beta", as tests/query_cli_test.cc makes it) and photo-like
// pictures of some of its views sorted into shape folders, one of them filed under the wrong shape
// and one without a hand; the text, --json (schema-checked) and --out outputs, and the errors;
// --hand on a mirrored photo, --keypoints, the photo-path flags, and the Slurm split's task and
// merge commands run by hand (the real Slurm is tests/slurm/evaluate_test.sh).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>

#include "base/json_schema.h"
#include "base/testing.h"
#include "format/manifest.h"
#include "format/roll.h"
#include "format/shard_writer.h"
#include "query/search_testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

using handdb::testing::CliRun;

// `handdb evaluate ARGS`, stdout and stderr captured.
CliRun Handdb(const std::string& args) {
  return handdb::testing::RunShell(std::string(HANDDB_BINARY) + " evaluate " + args);
}

class EvaluatePhotosCli : public ::testing::Test {
 protected:
  static constexpr uint32_t kViews = 24;  // views 0-11: alpha, 12-23: beta
  static constexpr uint32_t kRolls = 12;

  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() / ("handdb-pcli-" + std::to_string(getpid())));
    fs::remove_all(*dir_);
    fs::create_directories(*dir_ / "db");
    Manifest manifest;
    manifest.tool_version = "evaluate_photos_cli_test";
    manifest.rolls = kRolls;
    manifest.metadata["shapes"] = {{{"id", 0}, {"name", "alpha"}}, {{"id", 1}, {"name", "beta"}}};
    for (uint32_t s = 0; s < 2; ++s) {
      ShardWriter w;
      const fs::path shard = *dir_ / "db" / ("shard-0000" + std::to_string(s) + ".hdb");
      ASSERT_TRUE(w.Open(shard, ShardWriterOptions{}).ok());
      for (uint32_t i = 0; i < kViews / 2; ++i) {
        const uint32_t v = s * (kViews / 2) + i;
        ASSERT_TRUE(
            w.AddView(testing::SyntheticViewLabel(v, kViews / 2), testing::SyntheticEdgeSet(v, 300))
                .ok());
      }
      auto summary = w.Finish();
      ASSERT_TRUE(summary.ok());
      manifest.AddShard(*summary);
    }
    ASSERT_TRUE(WriteManifest(*dir_ / "db", manifest).ok());

    const fs::path photos = *dir_ / "photos";
    fs::create_directories(photos / "alpha");
    fs::create_directories(photos / "beta");
    ASSERT_TRUE(cv::imwrite((photos / "alpha" / "v03.png").string(), Photo(3, 2)));
    ASSERT_TRUE(cv::imwrite((photos / "alpha" / "v17.png").string(), Photo(17, 5)));  // a beta view
    ASSERT_TRUE(cv::imwrite((photos / "beta" / "v20.jpg").string(), Photo(20, 0)));
    ASSERT_TRUE(cv::imwrite((photos / "beta" / "blue.png").string(),
                            cv::Mat(80, 90, CV_8UC3, cv::Scalar(200, 60, 20))));
    std::ofstream(photos / "SOURCE.md") << "synthetic\n";
  }
  static void TearDownTestSuite() {
    if (std::getenv("HANDDB_KEEP_TEST_DIR") == nullptr) fs::remove_all(*dir_);
    delete dir_;
  }

  // View v rolled by r as a photo: a skin-coloured convex hull on a blue background with the edge
  // strokes drawn darker, kPx source px per normalised px, the normalised origin at pixel
  // (kX0, kY0).
  static constexpr double kPx = 1.5, kX0 = 220, kY0 = 210;
  static cv::Mat Photo(uint32_t v, uint32_t r) {
    std::vector<Point2f> rolled;
    RollPoints(testing::SyntheticEdgeSet(v, 300), RollAngle(r, kRolls), &rolled);
    cv::Mat edges = cv::Mat::zeros(420, 440, CV_8U);
    for (const auto& p : rolled) {
      edges.at<uint8_t>(static_cast<int>(std::lround(kY0 + kPx * p.y)),
                        static_cast<int>(std::lround(kX0 + kPx * p.x))) = 255;
    }
    std::vector<cv::Point> all, hull;
    cv::findNonZero(edges, all);
    cv::convexHull(all, hull);
    cv::Mat img(edges.size(), CV_8UC3, cv::Scalar(150, 110, 80));
    cv::fillConvexPoly(img, hull, cv::Scalar(120, 150, 210));
    // Strokes 7 px wide, 1/41 of the hand: thinner ones are under 2 px at the photo path's
    // 128 px working size and Canny does not see them (as tests/query_cli_test.cc).
    cv::Mat thick;
    cv::dilate(edges, thick, cv::Mat::ones(7, 7, CV_8U));
    img.setTo(cv::Scalar(70, 95, 150), thick);
    return img;
  }

  // Where Photo(v, r) shows view v's keypoints: the image frame of keypoints_image_px (pixel
  // centres at + 0.5), mirrored about the picture's vertical centre line for a flipped photo.
  static nlohmann::json TrueKeypoints(uint32_t v, uint32_t r, bool flipped) {
    const ViewLabel label =
        RollLabel(testing::SyntheticViewLabel(v, kViews / 2), RollAngle(r, kRolls));
    nlohmann::json kps = nlohmann::json::array();
    for (const auto& k : label.keypoints) {
      const double x = kX0 + kPx * k[0] + 0.5;
      kps.push_back({flipped ? 440 - x : x, kY0 + kPx * k[1] + 0.5});
    }
    return kps;
  }
  static double BoxDiagonal(const nlohmann::json& kps) {
    double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
    for (const auto& k : kps) {
      x0 = std::min(x0, k[0].get<double>());
      x1 = std::max(x1, k[0].get<double>());
      y0 = std::min(y0, k[1].get<double>());
      y1 = std::max(y1, k[1].get<double>());
    }
    return std::hypot(x1 - x0, y1 - y0);
  }
  static nlohmann::json ReadJson(const fs::path& path) {
    std::ifstream f(path);
    return nlohmann::json::parse(f);
  }

  static std::string Db() { return (*dir_ / "db").string(); }
  static std::string Photos() { return (*dir_ / "photos").string(); }
  static fs::path* dir_;
};
fs::path* EvaluatePhotosCli::dir_ = nullptr;

TEST_F(EvaluatePhotosCli, ScoresShapesWritesJsonAndImages) {
  const fs::path json_path = *dir_ / "report.json";
  const fs::path out = *dir_ / "out";
  CliRun r = Handdb(Db() + " --photos " + Photos() + " --threads 2 --json " + json_path.string() +
                    " --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  std::ifstream f(json_path);
  const auto doc = nlohmann::json::parse(f);
  const Status valid = ValidateJson(doc, "photo_evaluation.schema.json", json_path.string());
  EXPECT_TRUE(valid.ok()) << valid.message();
  EXPECT_EQ(doc["photo_count"], 4);
  EXPECT_EQ(doc["failed_inputs"], 1);
  // alpha/v03 and beta/v20 are found at rank 1; alpha/v17 is a beta view; beta/blue has no hand.
  EXPECT_EQ(doc["accuracy"][0]["k"], 1);
  EXPECT_EQ(doc["accuracy"][0]["hits"], 2);
  EXPECT_DOUBLE_EQ(doc["accuracy"][0]["rate"].get<double>(), 0.5);
  // Half the virtual views are alpha: chance at k = 1 is 0.5 for every photo.
  EXPECT_NEAR(doc["accuracy"][0]["chance"].get<double>(), 0.5, 1e-12);
  std::map<std::string, nlohmann::json> by_name;
  for (const auto& p : doc["photos"]) by_name[p["photo"]] = p;
  EXPECT_EQ(by_name["alpha/v03.png"]["rank"], 1);
  EXPECT_EQ(by_name["beta/v20.jpg"]["rank"], 1);
  EXPECT_EQ(by_name["alpha/v17.png"]["match_shapes"][0], "beta");
  EXPECT_NE(by_name["beta/blue.png"]["error"].get<std::string>().find("no hand"),
            std::string::npos);
  EXPECT_EQ(doc["confusion"]["cols"], (nlohmann::json{"alpha", "beta", "no hand"}));
  EXPECT_EQ(doc["confusion"]["counts"][0], (nlohmann::json{1, 1, 0}));
  EXPECT_EQ(doc["confusion"]["counts"][1], (nlohmann::json{0, 1, 1}));
  EXPECT_EQ(doc["shapes"][0]["top_wrong"], "beta");
  EXPECT_EQ(doc["shapes"][1]["top_wrong"], "no hand");
  // `handdb query`'s default: each photo and its mirror image searched; these are right hands.
  EXPECT_EQ(doc["search"]["hand"], "either");
  EXPECT_EQ(doc["search"]["query_options"]["input"], "auto");
  EXPECT_EQ(doc["top1_hands"], (nlohmann::json{{"right", 3}, {"left", 0}}));
  EXPECT_EQ(by_name["alpha/v03.png"]["top1"]["hand"], "right");
  EXPECT_TRUE(doc["keypoints"].is_null());

  EXPECT_NE(r.out.find("top-1"), std::string::npos);
  EXPECT_NE(r.out.find("chance"), std::string::npos);
  EXPECT_NE(r.out.find("beta/blue.png"), std::string::npos);  // listed as a failed photo
  EXPECT_NE(r.out.find("queries/s"), std::string::npos);
  for (const char* png : {"confusion.png", "successes.png", "failures.png"}) {
    EXPECT_FALSE(cv::imread((out / png).string()).empty()) << png;
  }
}

TEST_F(EvaluatePhotosCli, UnknownFolderIsAnErrorUnlessSkipped) {
  const fs::path photos = *dir_ / "photos-extra";
  fs::create_directories(photos / "alpha");
  fs::create_directories(photos / "gamma");
  ASSERT_TRUE(cv::imwrite((photos / "alpha" / "v05.png").string(), Photo(5, 1)));
  ASSERT_TRUE(cv::imwrite((photos / "gamma" / "v06.png").string(), Photo(6, 1)));
  CliRun r = Handdb(Db() + " --photos " + photos.string() + " -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(r.err.rfind("handdb evaluate: ", 0), 0u) << r.err;
  EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << r.err;
  EXPECT_NE(r.err.find("gamma"), std::string::npos);

  const fs::path json_path = *dir_ / "skipped.json";
  r = Handdb(Db() + " --photos " + photos.string() + " --skip-unknown -q --json " +
             json_path.string());
  ASSERT_EQ(r.code, 0) << r.err;
  std::ifstream f(json_path);
  const auto doc = nlohmann::json::parse(f);
  EXPECT_EQ(doc["skipped_folders"], (nlohmann::json{"gamma"}));
  EXPECT_EQ(doc["photo_count"], 1);
  EXPECT_EQ(doc["accuracy"][0]["hits"], 1);
}

// Files are read as `handdb query` reads them: a folder of edge images (a view's points drawn
// white on black) is scored like one of photos, each at rank 1 with D_c near 0.
TEST_F(EvaluatePhotosCli, ReadsEdgeImagesLikeQuery) {
  const fs::path photos = *dir_ / "edge-images";
  fs::create_directories(photos / "alpha");
  fs::create_directories(photos / "beta");
  auto edge_image = [](uint32_t v, uint32_t r) {
    std::vector<Point2f> rolled;
    RollPoints(testing::SyntheticEdgeSet(v, 300), RollAngle(r, kRolls), &rolled);
    cv::Mat edges = cv::Mat::zeros(400, 400, CV_8U);
    for (const auto& p : rolled) {
      edges.at<uint8_t>(static_cast<int>(std::lround(200 + p.y)),
                        static_cast<int>(std::lround(200 + p.x))) = 255;
    }
    return edges;
  };
  ASSERT_TRUE(cv::imwrite((photos / "alpha" / "e04.png").string(), edge_image(4, 3)));
  ASSERT_TRUE(cv::imwrite((photos / "beta" / "e15.png").string(), edge_image(15, 7)));
  const fs::path json_path = *dir_ / "edge-images.json";
  CliRun r = Handdb(Db() + " --photos " + photos.string() + " -q --json " + json_path.string());
  ASSERT_EQ(r.code, 0) << r.err;
  std::ifstream f(json_path);
  const auto doc = nlohmann::json::parse(f);
  EXPECT_EQ(doc["failed_inputs"], 0) << doc.dump();
  EXPECT_EQ(doc["accuracy"][0]["hits"], 2) << doc.dump();
  for (const auto& p : doc["photos"]) {
    EXPECT_EQ(p["rank"], 1) << p.dump();
    EXPECT_LT(p["match_distances"][0].get<double>(), 1.0) << p.dump();
  }
}

TEST_F(EvaluatePhotosCli, BadUsage) {
  EXPECT_EQ(Handdb(Db()).code, 2);                                             // neither
  EXPECT_EQ(Handdb(Db() + " " + Photos() + " --photos " + Photos()).code, 2);  // both
  EXPECT_EQ(Handdb(Db() + " --photos " + Photos() + " --d 20").code, 2);       // test-set flag
  EXPECT_EQ(Handdb(Db() + " --photos " + Photos() + " --threads 0").code, 2);
  CliRun r = Handdb(Db() + " --photos " + (*dir_ / "nothing").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("nothing"), std::string::npos);
}

// A flipped photo shows a left hand: --hand either finds it (mirrored back: its top-1 keypoints lie
// where the flipped photo shows them), --hand right does not.
TEST_F(EvaluatePhotosCli, EitherHandFindsAMirroredPhotoAsALeftHand) {
  const fs::path photos = *dir_ / "photos-left";
  fs::create_directories(photos / "alpha");
  cv::Mat flipped;
  cv::flip(Photo(9, 4), flipped, 1);
  ASSERT_TRUE(cv::imwrite((photos / "alpha" / "left.png").string(), flipped));
  ASSERT_TRUE(cv::imwrite((photos / "alpha" / "right.png").string(), Photo(9, 4)));
  const fs::path either = *dir_ / "left-either.json";
  CliRun r = Handdb(Db() + " --photos " + photos.string() + " -q --json " + either.string());
  ASSERT_EQ(r.code, 0) << r.err;
  auto doc = ReadJson(either);
  ASSERT_EQ(doc["photos"][0]["photo"], "alpha/left.png");
  const nlohmann::json left = doc["photos"][0];  // a copy: doc is read again below
  EXPECT_EQ(left["rank"], 1) << left.dump();
  EXPECT_EQ(left["top1"]["view_id"], 9);
  EXPECT_EQ(left["top1"]["roll"], 4);
  EXPECT_EQ(left["top1"]["hand"], "left");
  EXPECT_EQ(left["match_hands"][0], "left");
  EXPECT_EQ(doc["photos"][1]["top1"]["hand"], "right");
  EXPECT_EQ(doc["top1_hands"], (nlohmann::json{{"right", 1}, {"left", 1}}));
  // Keypoints in the photo's pixels, mirrored back: within a few px of where the photo shows them
  // (the photo's normalisation is re-derived from its silhouette, so not exactly).
  const auto truth = TrueKeypoints(9, 4, /*flipped=*/true);
  const auto& kps = left["top1"]["keypoints_image_px"];
  for (int k = 0; k < kNumKeypoints; ++k) {
    EXPECT_NEAR(kps[k][0].get<double>(), truth[k][0].get<double>(), 6) << k;
    EXPECT_NEAR(kps[k][1].get<double>(), truth[k][1].get<double>(), 6) << k;
  }

  const fs::path right = *dir_ / "left-right.json";
  r = Handdb(Db() + " --photos " + photos.string() + " --hand right -q --json " + right.string());
  ASSERT_EQ(r.code, 0) << r.err;
  doc = ReadJson(right);
  EXPECT_EQ(doc["search"]["hand"], "right");
  EXPECT_EQ(doc["top1_hands"]["left"], 0);
  // (Canny finds both sides of a stroke, so the left match is ~3.7 px, not ~0; the best right-hand
  // view is ~7.)
  EXPECT_GT(doc["photos"][0]["match_distances"][0].get<double>(),
            1.5 * left["match_distances"][0].get<double>());

  r = Handdb(Db() + " --photos " + photos.string() + " --hand left -q");
  EXPECT_EQ(r.code, 0) << r.err;
  r = Handdb(Db() + " --photos " + photos.string() + " --hand up -q");
  EXPECT_EQ(r.code, 2);
}

TEST_F(EvaluatePhotosCli, KeypointsFileGivesTheTwoDimensionalError) {
  // alpha/v03.png annotated where it shows the keypoints, beta/v20.jpg 30 px to the right of
  // them, with the wrist marked not visible; alpha/v17.png and beta/blue.png not annotated.
  nlohmann::json exact = TrueKeypoints(3, 2, false);
  nlohmann::json shifted = TrueKeypoints(20, 0, false);
  for (auto& k : shifted) k[0] = k[0].get<double>() + 30;
  shifted[0].push_back(false);
  const fs::path kp = *dir_ / "keypoints.json";
  std::ofstream(kp) << nlohmann::json{{"format", "handdb-photo-keypoints"},
                                      {"version", 1},
                                      {"images",
                                       {{"alpha/v03.png", exact}, {"beta/v20.jpg", shifted}}}}
                           .dump();
  const fs::path json_path = *dir_ / "keypoints-report.json";
  CliRun r = Handdb(Db() + " --photos " + Photos() + " --keypoints " + kp.string() + " --json " +
                    json_path.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const auto doc = ReadJson(json_path);
  const Status valid = ValidateJson(doc, "photo_evaluation.schema.json", json_path.string());
  EXPECT_TRUE(valid.ok()) << valid.message();
  const auto& k = doc["keypoints"];
  EXPECT_EQ(k["file"], kp.string());
  EXPECT_EQ(k["annotated_photos"], 2);
  EXPECT_EQ(k["top1"]["photos"], 2);
  std::map<std::string, nlohmann::json> by_name;
  for (const auto& p : doc["photos"]) by_name[p["photo"]] = p;
  EXPECT_EQ(by_name["alpha/v03.png"]["annotated_keypoints"], 21);
  EXPECT_EQ(by_name["beta/v20.jpg"]["annotated_keypoints"], 20);
  EXPECT_EQ(by_name["alpha/v17.png"]["annotated_keypoints"], 0);
  EXPECT_FALSE(by_name["alpha/v17.png"].contains("keypoints"));
  const double exact_error = by_name["alpha/v03.png"]["keypoints"]["top1_error"].get<double>();
  EXPECT_LT(exact_error, 0.02);
  // 30 px over the hand size (the diagonal of the 20 visible keypoints' box), give or take the
  // few px the photo's re-derived normalisation is off.
  shifted.erase(shifted.begin());
  const double expected = 30 / BoxDiagonal(shifted);
  const auto& kb = by_name["beta/v20.jpg"]["keypoints"];
  EXPECT_NEAR(kb["hand_size_px"].get<double>(), BoxDiagonal(shifted), 1e-3);
  EXPECT_NEAR(kb["top1_error"].get<double>(), expected, 0.02);
  EXPECT_TRUE(kb["top1_distances_px"][0].is_null());
  EXPECT_LE(kb["best10_error"].get<double>(), kb["top1_error"].get<double>());
  EXPECT_NE(r.out.find("2D keypoints (" + kp.string() + "): 2 of 4 photos annotated"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("PCK@0.05"), std::string::npos) << r.out;
}

TEST_F(EvaluatePhotosCli, BadKeypointFilesAreOneLineErrors) {
  auto expect_error = [](const std::string& text, const std::string& what) {
    const fs::path kp = *dir_ / "bad-keypoints.json";
    std::ofstream(kp) << text;
    CliRun r = Handdb(Db() + " --photos " + Photos() + " -q --keypoints " + kp.string());
    EXPECT_EQ(r.code, 1) << what;
    EXPECT_EQ(r.err.rfind("handdb evaluate: " + kp.string() + ": ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(what), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << r.err;
  };
  nlohmann::json kps = TrueKeypoints(3, 2, false);
  auto doc = [&](const std::string& key, const nlohmann::json& value) {
    return nlohmann::json{
        {"format", "handdb-photo-keypoints"}, {"version", 1}, {"images", {{key, value}}}}
        .dump();
  };
  expect_error(doc("alpha/v99.png", kps), "images[\"alpha/v99.png\"]: no such image in");
  expect_error(doc("v03.png", kps), "images[\"v03.png\"]: no such image in");
  nlohmann::json short_list = kps;
  short_list.erase(short_list.begin());
  expect_error(doc("alpha/v03.png", short_list), "minItems is 21");
  expect_error("{\"format\": ", "line 1");
  CliRun r = Handdb(Db() + " --photos " + Photos() + " -q --keypoints " +
                    (*dir_ / "no-such.json").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("no-such.json"), std::string::npos) << r.err;
}

// The photo-path flags are `handdb query`'s, bound to the same options and checked alike.
TEST_F(EvaluatePhotosCli, PhotoFlagsReachThePhotoPath) {
  // A skin box no pixel fits: no photo has a hand any more.
  const fs::path json_path = *dir_ / "no-skin.json";
  CliRun r = Handdb(Db() + " --photos " + Photos() + " -q --skin 0,0,0,0,0,0 --canny 30,90 " +
                    "--contour-clearance 1 --edges-outside --json " + json_path.string());
  ASSERT_EQ(r.code, 0) << r.err;
  auto doc = ReadJson(json_path);
  EXPECT_EQ(doc["failed_inputs"], 4);
  const auto& q = doc["search"]["query_options"];
  EXPECT_EQ(q["skin"], (nlohmann::json{0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(q["canny"], (nlohmann::json{30, 90}));
  EXPECT_EQ(q["contour_clearance_px"], 1);
  EXPECT_EQ(q["interior_edges_only"], false);
  // --roi keeps the hand out: the same.
  r = Handdb(Db() + " --photos " + Photos() + " -q --roi 0,0,20,20 --json " + json_path.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(ReadJson(json_path)["failed_inputs"], 4);

  for (const std::string& bad : {std::string("--skin 1,2,3"),
                                 std::string("--skin 0,300,0,1,0,1"),
                                 std::string("--canny 9,1"),
                                 std::string("--roi 1,2"),
                                 std::string("--input clean")}) {
    r = Handdb(Db() + " --photos " + Photos() + " -q " + bad);
    EXPECT_EQ(r.code, 2) << bad;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << bad << ": " << r.err;
  }
  EXPECT_EQ(Handdb(Db() + " --photos " + Photos() + " -q --contour-clearance 99").code, 2);
  // ... and belong to --photos: with a TESTSET they are refused before it is read.
  for (const std::string& flag : {std::string("--hand left"),
                                  std::string("--skin 0,255,0,255,0,255"),
                                  std::string("--keypoints k.json"),
                                  std::string("--out o")}) {
    r = Handdb(Db() + " " + (*dir_ / "no-testset").string() + " " + flag);
    EXPECT_EQ(r.code, 2) << flag;
    EXPECT_NE(r.err.find("applies to --photos"), std::string::npos) << r.err;
  }
  r = Handdb(Db() + " " + (*dir_ / "no-testset").string() + " --input edges");
  EXPECT_EQ(r.code, 2);
}

// The Slurm split without Slurm: the array tasks' and the merge job's commands, run by hand, give
// the report of a local run (but its timing); the dry run writes scripts that run them.
TEST_F(EvaluatePhotosCli, TaskPartsMergeIntoTheLocalReport) {
  const fs::path work = *dir_ / "work";
  const fs::path local_json = *dir_ / "split-local.json";
  const std::string common =
      " --photos " + Photos() + " --hand either --skin 40,255,133,173,77,127";
  CliRun local = Handdb(Db() + common + " --threads 1 --json " + local_json.string() + " --out " +
                        (*dir_ / "split-local").string());
  ASSERT_EQ(local.code, 0) << local.err;
  auto unit = [&](const std::string& args) {
    const std::string cmd = std::string(HANDDB_BINARY) + " unit " + args + " >" +
                            (*dir_ / "unit.out").string() + " 2>&1";
    return std::system(cmd.c_str());
  };
  const std::string split = " --tasks 3 --work " + work.string() + " --input auto";
  for (int t = 0; t < 3; ++t) {
    ASSERT_EQ(unit("evaluate-photos " + Db() + common + split + " -q --task " + std::to_string(t)),
              0);
  }
  // A task whose part is complete keeps it.
  ASSERT_EQ(unit("evaluate-photos " + Db() + common + split + " -q --task 1"), 0);
  std::ifstream kept(*dir_ / "unit.out");
  EXPECT_NE(std::string(std::istreambuf_iterator<char>(kept), {}).find("already complete"),
            std::string::npos);
  const fs::path merged_json = *dir_ / "split-merged.json";
  ASSERT_EQ(unit("evaluate-photos-merge " + Db() + common + split + " --json " +
                 merged_json.string() + " --out " + (*dir_ / "split-merged").string()),
            0);
  auto strip = [](nlohmann::json doc) {
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
    return doc.dump(1);
  };
  EXPECT_EQ(strip(ReadJson(merged_json)), strip(ReadJson(local_json)));
  std::ifstream text(work / "report.txt");
  std::string merged_text(std::istreambuf_iterator<char>(text), {});
  auto without_speed = [](std::string t) {
    const size_t at = t.find("\nspeed ");
    return t.substr(0, at) + t.substr(t.find('\n', at + 1));
  };
  EXPECT_EQ(without_speed(merged_text), without_speed(local.out));
  for (const char* png : {"confusion.png", "successes.png", "failures.png"}) {
    EXPECT_FALSE(cv::imread((*dir_ / "split-merged" / png).string()).empty()) << png;
  }
  // Another hand makes parts of another evaluation: refused, one line naming the part.
  EXPECT_NE(unit("evaluate-photos-merge " + Db() + " --photos " + Photos() + " --hand right" +
                 split + " -q"),
            0);
  std::ifstream err(*dir_ / "unit.out");
  const std::string refused(std::istreambuf_iterator<char>(err), {});
  EXPECT_NE(refused.find("part-00000.json: a part of another evaluation: made with other "
                         "evaluation options (hand: \"either\" vs \"right\")"),
            std::string::npos)
      << refused;

  const fs::path no_annotations = *dir_ / "dry-keypoints.json";
  std::ofstream(no_annotations)
      << R"({"format": "handdb-photo-keypoints", "version": 1, "images": {}})";
  CliRun dry = Handdb(Db() + common + " --keypoints " + no_annotations.string() +
                      " --slurm --dry-run --tasks 2 --work " + (*dir_ / "dry").string());
  ASSERT_EQ(dry.code, 0) << dry.err;
  EXPECT_NE(dry.out.find("dry run: 4 photos in 2 tasks, 2 to run (0-1)"), std::string::npos)
      << dry.out;
  EXPECT_NE(dry.out.find("--dependency=afterok:"), std::string::npos) << dry.out;
  std::ifstream script(*dir_ / "dry" / "evaluate-array.sbatch");
  const std::string array(std::istreambuf_iterator<char>(script), {});
  EXPECT_NE(array.find("'evaluate-photos'"), std::string::npos) << array;
  EXPECT_NE(array.find("'--keypoints'"), std::string::npos) << array;
  EXPECT_NE(array.find("'--hand' 'either'"), std::string::npos) << array;
  EXPECT_EQ(Handdb(Db() + common + " --slurm --dry-run --tasks 5").code, 2);  // > 4 photos
  EXPECT_EQ(Handdb(Db() + common + " --tasks 2").code, 2);                    // needs --slurm
}

}  // namespace
}  // namespace handdb
