// `handdb query` end to end: a database written with ShardWriter + WriteManifest, an
// edge image and a photo-like image of one of its views, the table / --json / --sheet outputs,
// brute force == pruned through the CLI, and the one-line errors with exit codes.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <vector>

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

// `handdb query ARGS`, stdout and stderr captured.
CliRun Handdb(const std::string& args) {
  return handdb::testing::RunShell(std::string(HANDDB_BINARY) + " query " + args);
}

class QueryCli : public ::testing::Test {
 protected:
  static constexpr uint32_t kViews = 24;
  static constexpr uint32_t kRolls = 12;

  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() / ("handdb-qcli-" + std::to_string(getpid())));
    fs::create_directories(*dir_ / "db");
    Manifest manifest;
    manifest.tool_version = "query_cli_test";
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
  }
  static void TearDownTestSuite() {
    if (std::getenv("HANDDB_KEEP_TEST_DIR") == nullptr) fs::remove_all(*dir_);
    delete dir_;
  }

  // View v rolled by r, drawn at 1.5 source px per normalised px into a w x h image.
  static cv::Mat Draw(uint32_t v, uint32_t r, bool photo) {
    const auto pts = testing::SyntheticEdgeSet(v, 300);
    std::vector<Point2f> rolled;
    RollPoints(pts, RollAngle(r, kRolls), &rolled);
    cv::Mat edges = cv::Mat::zeros(420, 440, CV_8U);
    std::vector<cv::Point> poly;
    for (const auto& p : rolled) {
      const int x = static_cast<int>(std::lround(220 + 1.5 * p.x));
      const int y = static_cast<int>(std::lround(210 + 1.5 * p.y));
      edges.at<uint8_t>(y, x) = 255;
    }
    if (!photo) return edges;
    // A skin-coloured blob (the convex hull of the points) with the strokes drawn darker.
    std::vector<cv::Point> all;
    cv::findNonZero(edges, all);
    std::vector<cv::Point> hull;
    cv::convexHull(all, hull);
    cv::Mat img(edges.size(), CV_8UC3, cv::Scalar(150, 110, 80));
    cv::fillConvexPoly(img, hull, cv::Scalar(120, 150, 210));
    // Strokes 7 px wide (1/41 of this ~290 px hand), as a photographed finger border would be.
    // The photo path works at a 128 px hand (docs/query.md), where a stroke of 1/96 of the hand
    // (3 px here) is under 1.5 px wide there and Canny no longer sees it.
    cv::Mat thick;
    cv::dilate(edges, thick, cv::Mat::ones(7, 7, CV_8U));
    img.setTo(cv::Scalar(70, 95, 150), thick);
    return img;
  }

  static fs::path* dir_;
};
fs::path* QueryCli::dir_ = nullptr;

TEST_F(QueryCli, EdgeImageJsonTableSheetAndBruteForce) {
  const fs::path img = *dir_ / "q.png";
  ASSERT_TRUE(cv::imwrite(img.string(), Draw(9, 4, false)));
  const std::string db = (*dir_ / "db").string();

  CliRun json_run = Handdb(db + " " + img.string() + " --json --top 5 --threads 2");
  ASSERT_EQ(json_run.code, 0) << json_run.err;
  const auto doc = nlohmann::json::parse(json_run.out);
  EXPECT_TRUE(ValidateJson(doc, "query_result.schema.json", "output").ok());
  EXPECT_EQ(doc["input_kind"], "edges");
  ASSERT_EQ(doc["matches"].size(), 5u);
  EXPECT_EQ(doc["matches"][0]["view_id"], 9);
  EXPECT_EQ(doc["matches"][0]["roll"], 4);
  EXPECT_EQ(doc["matches"][0]["shape_name"], "alpha");
  EXPECT_EQ(doc["matches"][0]["joint_angles"].size(), 20u);
  EXPECT_EQ(doc["matches"][0]["keypoints"].size(), 21u);

  CliRun brute =
      Handdb(db + " " + img.string() + " --json --top 5 --bruteforce --kdtree pcl --threads 1");
  ASSERT_EQ(brute.code, 0) << brute.err;
  const auto bdoc = nlohmann::json::parse(brute.out);
  for (size_t i = 0; i < 5; ++i) {
    EXPECT_EQ(bdoc["matches"][i]["view_id"], doc["matches"][i]["view_id"]);
    EXPECT_EQ(bdoc["matches"][i]["roll"], doc["matches"][i]["roll"]);
    EXPECT_EQ(bdoc["matches"][i]["distance"], doc["matches"][i]["distance"]);
  }

  const fs::path sheet = *dir_ / "sheet.png";
  CliRun table = Handdb(db + " " + img.string() + " --top 3 --sheet " + sheet.string());
  ASSERT_EQ(table.code, 0) << table.err;
  EXPECT_NE(table.out.find("rank"), std::string::npos);
  EXPECT_NE(table.out.find("alpha"), std::string::npos);
  EXPECT_FALSE(cv::imread(sheet.string()).empty());
}

TEST_F(QueryCli, PhotoFindsTheView) {
  const fs::path img = *dir_ / "photo.png";
  ASSERT_TRUE(cv::imwrite(img.string(), Draw(17, 2, true)));
  CliRun r = Handdb((*dir_ / "db").string() + " " + img.string() + " --json --top 3");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto doc = nlohmann::json::parse(r.out);
  EXPECT_EQ(doc["input_kind"], "photo");
  EXPECT_EQ(doc["matches"][0]["view_id"], 17);
  EXPECT_EQ(doc["matches"][0]["roll"], 2);
}

// A left hand is a mirrored right hand: the mirrored edge image of view 9 comes back as view 9,
// hand "left", at D_c ~ 0 under --hand left and the default (either); its keypoints in the input
// image are the unmirrored answer's mirrored about the image's vertical centre line.
TEST_F(QueryCli, MirroredImageIsALeftHandWithKeypointsInTheImage) {
  const cv::Mat right = Draw(9, 4, false);
  cv::Mat left;
  cv::flip(right, left, 1);
  const fs::path right_png = *dir_ / "right.png";
  const fs::path left_png = *dir_ / "left.png";
  ASSERT_TRUE(cv::imwrite(right_png.string(), right));
  ASSERT_TRUE(cv::imwrite(left_png.string(), left));
  const std::string db = (*dir_ / "db").string();

  CliRun r = Handdb(db + " " + right_png.string() + " --json --top 3 --hand right");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto rdoc = nlohmann::json::parse(r.out);
  EXPECT_TRUE(ValidateJson(rdoc, "query_result.schema.json", "output").ok());
  const auto& rm = rdoc["matches"][0];
  EXPECT_EQ(rm["view_id"], 9);
  EXPECT_EQ(rm["hand"], "right");
  EXPECT_EQ(rdoc["stats"]["searches"], 1);
  // keypoints_image_px undoes the normalisation of the keypoints.
  const double scale = rdoc["query"]["scale"];
  const double cx = rdoc["query"]["centre_px"][0];
  const double cy = rdoc["query"]["centre_px"][1];
  ASSERT_EQ(rm["keypoints_image_px"].size(), 21u);
  for (size_t k = 0; k < 21; ++k) {
    EXPECT_NEAR(rm["keypoints_image_px"][k][0].get<double>(),
                rm["keypoints"][k][0].get<double>() / scale + cx,
                1e-3);
    EXPECT_NEAR(rm["keypoints_image_px"][k][1].get<double>(),
                rm["keypoints"][k][1].get<double>() / scale + cy,
                1e-3);
  }

  for (const std::string hand : {" --hand left", " --hand either", ""}) {
    CliRun l = Handdb(db + " " + left_png.string() + " --json --top 3" + hand);
    ASSERT_EQ(l.code, 0) << l.err;
    const auto ldoc = nlohmann::json::parse(l.out);
    EXPECT_TRUE(ValidateJson(ldoc, "query_result.schema.json", "output").ok());
    EXPECT_EQ(ldoc["stats"]["searches"], hand == " --hand left" ? 1 : 2) << hand;
    const auto& lm = ldoc["matches"][0];
    EXPECT_EQ(lm["view_id"], 9) << hand;
    EXPECT_EQ(lm["roll"], 4) << hand;
    EXPECT_EQ(lm["hand"], "left") << hand;
    // The drawn image is not exactly the view (1.5x, rounded), but its mirror is as far away.
    EXPECT_NEAR(lm["distance"].get<double>(), rm["distance"].get<double>(), 0.05) << hand;
    for (size_t k = 0; k < 21; ++k) {
      EXPECT_NEAR(lm["keypoints_image_px"][k][0].get<double>(),
                  right.cols - rm["keypoints_image_px"][k][0].get<double>(),
                  0.5)
          << hand << " keypoint " << k;
      EXPECT_NEAR(lm["keypoints_image_px"][k][1].get<double>(),
                  rm["keypoints_image_px"][k][1].get<double>(),
                  0.5)
          << hand << " keypoint " << k;
    }
  }
  CliRun table = Handdb(db + " " + left_png.string() + " --top 2");
  ASSERT_EQ(table.code, 0) << table.err;
  EXPECT_NE(table.out.find("left"), std::string::npos);
  EXPECT_EQ(Handdb(db + " " + left_png.string() + " --hand both").code, 2);
}

// Lines of a JSON Lines output, parsed.
std::vector<nlohmann::json> JsonLines(const std::string& text) {
  std::vector<nlohmann::json> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

// A batch: the database opened once for several pictures, a directory or a list on stdin; the
// answers in input order, each the single query's; a bad picture in the middle reported on one
// line (and in its place in JSON Lines) without stopping the others; exit 1 when any failed.
TEST_F(QueryCli, BatchKeepsOrderAndReportsBadPictures) {
  const fs::path dir = *dir_ / "batch";
  fs::create_directories(dir);
  const fs::path a = dir / "a.png", bad = dir / "bad.jpg", c = dir / "c.PNG";
  ASSERT_TRUE(cv::imwrite(a.string(), Draw(9, 4, false)));
  ASSERT_TRUE(cv::imwrite((*dir_ / "c.png").string(), Draw(17, 2, false)));
  fs::rename(*dir_ / "c.png", c);  // an upper-case extension is a picture too
  {
    std::ofstream f(bad);
    f << "not a jpeg";
    std::ofstream notes(dir / "notes.txt");
    notes << "not a picture: a directory's listing skips it";
  }
  const std::string db = (*dir_ / "db").string();
  auto one_error_line = [](const CliRun& r, const fs::path& file) {
    return r.err.rfind("handdb query: ", 0) == 0 && r.err.find('\n') == r.err.size() - 1 &&
           r.err.find(file.filename().string()) != std::string::npos;
  };

  CliRun r = Handdb(db + " " + a.string() + " " + bad.string() + " " + c.string() +
                    " --json --top 3 --threads 2");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(one_error_line(r, bad)) << r.err;
  auto lines = JsonLines(r.out);
  ASSERT_EQ(lines.size(), 3u) << r.out;
  for (const auto& line : lines) {
    const Status valid = ValidateJson(line, "query_batch_line.schema.json", "line");
    EXPECT_TRUE(valid.ok()) << valid.message();
  }
  EXPECT_EQ(lines[0]["picture"], a.string());
  EXPECT_EQ(lines[0]["image"], a.string());
  EXPECT_EQ(lines[0]["matches"][0]["view_id"], 9);
  EXPECT_EQ(lines[0]["matches"][0]["roll"], 4);
  EXPECT_EQ(lines[1]["picture"], bad.string());
  EXPECT_NE(lines[1]["error"].get<std::string>().find("bad.jpg"), std::string::npos);
  EXPECT_FALSE(lines[1].contains("matches"));
  EXPECT_EQ(lines[2]["picture"], c.string());
  EXPECT_EQ(lines[2]["matches"][0]["view_id"], 17);
  EXPECT_EQ(lines[2]["matches"][0]["roll"], 2);
  // Each answer is the single query's.
  CliRun single = Handdb(db + " " + c.string() + " --json --top 3 --threads 2");
  ASSERT_EQ(single.code, 0) << single.err;
  const auto doc = nlohmann::json::parse(single.out);
  EXPECT_FALSE(doc.contains("picture"));
  EXPECT_EQ(lines[2]["matches"], doc["matches"]);
  EXPECT_EQ(lines[2]["query"], doc["query"]);
  EXPECT_EQ(lines[2]["options"], doc["options"]);

  // A directory: its pictures sorted by name, not notes.txt.
  r = Handdb(db + " " + dir.string() + " --json --top 1 --threads 1");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(one_error_line(r, bad)) << r.err;
  lines = JsonLines(r.out);
  ASSERT_EQ(lines.size(), 3u) << r.out;
  EXPECT_EQ(lines[0]["picture"], a.string());
  EXPECT_EQ(lines[1]["picture"], bad.string());
  EXPECT_EQ(lines[2]["picture"], c.string());

  // A list on stdin, in its order (empty lines skipped); all good: exit 0. Four pictures: the
  // batch prepares the exact search's centre fields, and the answers stay the single query's.
  const fs::path list = *dir_ / "list.txt";
  {
    std::ofstream f(list);
    f << c.string() << "\n\n" << a.string() << "\r\n" << c.string() << "\n" << a.string() << "\n";
  }
  r = Handdb(db + " - --json --top 3 --threads 2 < " + list.string());
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  lines = JsonLines(r.out);
  ASSERT_EQ(lines.size(), 4u) << r.out;
  for (size_t i : {0u, 2u}) {
    EXPECT_EQ(lines[i]["picture"], c.string());
    EXPECT_EQ(lines[i]["matches"], doc["matches"]);
  }
  EXPECT_EQ(lines[1]["picture"], a.string());
  EXPECT_EQ(lines[3]["picture"], a.string());

  // Tables under a header line naming each picture; --batch makes one picture a batch.
  r = Handdb(db + " " + a.string() + " " + c.string() + " --top 2");
  EXPECT_EQ(r.code, 0) << r.err;
  const size_t head_a = r.out.find("picture: " + a.string() + "\n");
  const size_t head_c = r.out.find("picture: " + c.string() + "\n");
  ASSERT_NE(head_a, std::string::npos) << r.out;
  ASSERT_NE(head_c, std::string::npos) << r.out;
  EXPECT_LT(head_a, head_c);
  EXPECT_NE(r.out.find("rank", head_c), std::string::npos);
  r = Handdb(db + " " + a.string() + " --batch --json --top 1");
  EXPECT_EQ(r.code, 0) << r.err;
  ASSERT_EQ(JsonLines(r.out).size(), 1u);
  EXPECT_EQ(JsonLines(r.out)[0]["picture"], a.string());

  // One contact sheet and one mask belong to one picture; an empty list is an error.
  EXPECT_EQ(Handdb(db + " " + dir.string() + " --sheet " + (*dir_ / "s.png").string()).code, 2);
  EXPECT_EQ(Handdb(db + " " + a.string() + " " + c.string() + " --mask " + a.string()).code, 2);
  r = Handdb(db + " - < /dev/null");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("no pictures"), std::string::npos) << r.err;
}

TEST_F(QueryCli, ErrorsAreOneLineWithExitCodes) {
  const std::string db = (*dir_ / "db").string();
  auto one_line = [](const CliRun& r) {
    return r.err.rfind("handdb query: ", 0) == 0 && r.err.find('\n') == r.err.size() - 1;
  };
  {
    std::ofstream f(*dir_ / "garbage.jpg");
    f << "not a jpeg";
  }
  CliRun r = Handdb(db + " " + (*dir_ / "garbage.jpg").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(one_line(r)) << r.err;
  EXPECT_NE(r.err.find("garbage.jpg"), std::string::npos);

  ASSERT_TRUE(cv::imwrite((*dir_ / "blue.png").string(),
                          cv::Mat(80, 90, CV_8UC3, cv::Scalar(200, 60, 20))));
  r = Handdb(db + " " + (*dir_ / "blue.png").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(one_line(r)) << r.err;
  EXPECT_NE(r.err.find("no hand"), std::string::npos);

  r = Handdb((*dir_ / "nodb").string() + " " + (*dir_ / "blue.png").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(one_line(r)) << r.err;

  // A database whose shard is truncated fails its open checks.
  fs::copy(*dir_ / "db", *dir_ / "bad", fs::copy_options::recursive);
  fs::resize_file(*dir_ / "bad" / "shard-00001.hdb", 1000);
  ASSERT_TRUE(cv::imwrite((*dir_ / "e.png").string(), Draw(3, 0, false)));
  r = Handdb((*dir_ / "bad").string() + " " + (*dir_ / "e.png").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(one_line(r)) << r.err;
  EXPECT_NE(r.err.find("shard-00001.hdb"), std::string::npos);

  EXPECT_EQ(Handdb(db + " " + (*dir_ / "e.png").string() + " --top 0").code, 2);
  EXPECT_EQ(Handdb(db + " " + (*dir_ / "e.png").string() + " --roi 1,2,3").code, 2);
  EXPECT_EQ(Handdb(db).code, 2);
  EXPECT_EQ(Handdb("--help").code, 0);
}

}  // namespace
}  // namespace handdb
