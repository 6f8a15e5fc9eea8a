// `handdb evaluate DB --photos DIR` end to end (issue 16): a synthetic database (ShardWriter +
// WriteManifest, shapes "alpha" and "beta", as tests/query_cli_test.cc makes it) and photo-like
// pictures of some of its views sorted into shape folders, one of them filed under the wrong shape
// and one without a hand; the text, --json (schema-checked) and --out outputs, and the errors.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>

#include "base/json_schema.h"
#include "format/manifest.h"
#include "format/roll.h"
#include "format/shard_writer.h"
#include "query/search_testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

struct CliRun {
  int code = -1;
  std::string out;
  std::string err;
};

CliRun Handdb(const std::string& args) {
  static int n = 0;
  const std::string tag = std::to_string(getpid()) + "-" + std::to_string(n++);
  const fs::path out = fs::temp_directory_path() / ("handdb-pcli-out-" + tag);
  const fs::path err = fs::temp_directory_path() / ("handdb-pcli-err-" + tag);
  const std::string cmd =
      std::string(HANDDB_BINARY) + " evaluate " + args + " >" + out.string() + " 2>" + err.string();
  const int status = std::system(cmd.c_str());
  CliRun r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream fo(out), fe(err);
  std::stringstream so, se;
  so << fo.rdbuf();
  se << fe.rdbuf();
  r.out = so.str();
  r.err = se.str();
  fs::remove(out);
  fs::remove(err);
  return r;
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
  // strokes drawn darker, 1.5 source px per normalised px.
  static cv::Mat Photo(uint32_t v, uint32_t r) {
    std::vector<Point2f> rolled;
    RollPoints(testing::SyntheticEdgeSet(v, 300), RollAngle(r, kRolls), &rolled);
    cv::Mat edges = cv::Mat::zeros(420, 440, CV_8U);
    for (const auto& p : rolled) {
      edges.at<uint8_t>(static_cast<int>(std::lround(210 + 1.5 * p.y)),
                        static_cast<int>(std::lround(220 + 1.5 * p.x))) = 255;
    }
    std::vector<cv::Point> all, hull;
    cv::findNonZero(edges, all);
    cv::convexHull(all, hull);
    cv::Mat img(edges.size(), CV_8UC3, cv::Scalar(150, 110, 80));
    cv::fillConvexPoly(img, hull, cv::Scalar(120, 150, 210));
    cv::Mat thick;
    cv::dilate(edges, thick, cv::Mat::ones(3, 3, CV_8U));
    img.setTo(cv::Scalar(70, 95, 150), thick);
    return img;
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
  EXPECT_EQ(Handdb(Db()).code, 2);                                               // neither
  EXPECT_EQ(Handdb(Db() + " " + Photos() + " --photos " + Photos()).code, 2);    // both
  EXPECT_EQ(Handdb(Db() + " --photos " + Photos() + " --input photo").code, 2);  // test-set flag
  EXPECT_EQ(Handdb(Db() + " --photos " + Photos() + " --threads 0").code, 2);
  CliRun r = Handdb(Db() + " --photos " + (*dir_ / "nothing").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("nothing"), std::string::npos);
}

}  // namespace
}  // namespace handdb
