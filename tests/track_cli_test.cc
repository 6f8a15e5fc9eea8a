// `handdb track` end to end: a database written with ShardWriter + WriteManifest, a folder of
// edge-image frames of one of its views turning (one frame missing from the numbering, one not
// a picture), the JSON lines checked against their schema, --out, --overlay, a video through the
// video plugin, and the one-line errors with exit codes.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
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
using json = nlohmann::json;

using handdb::testing::CliRun;

// `ENV handdb track ARGS`, stdout and stderr captured.
CliRun Handdb(const std::string& args, const std::string& env = "") {
  return handdb::testing::RunShell(env + " " + std::string(HANDDB_BINARY) + " track " + args);
}

std::vector<json> Lines(const std::string& text) {
  std::vector<json> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) out.push_back(json::parse(line));
  }
  return out;
}

constexpr uint32_t kViews = 24;
constexpr uint32_t kRolls = 64;  // 5.6 degrees apart
constexpr uint32_t kView = 9;

class TrackCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(testing::TempDir("track_cli"));
    fs::create_directories(*dir_ / "db");
    Manifest manifest;
    manifest.tool_version = "track_cli_test";
    manifest.rolls = kRolls;
    manifest.metadata["shapes"] = {{{"id", 0}, {"name", "alpha"}}, {{"id", 1}, {"name", "beta"}}};
    ShardWriter w;
    ASSERT_TRUE(w.Open(*dir_ / "db" / "shard-00000.hdb", ShardWriterOptions{}).ok());
    for (uint32_t v = 0; v < kViews; ++v) {
      ASSERT_TRUE(
          w.AddView(testing::SyntheticViewLabel(v, kViews / 2), testing::SyntheticEdgeSet(v, 300))
              .ok());
    }
    auto summary = w.Finish();
    ASSERT_TRUE(summary.ok());
    manifest.AddShard(*summary);
    ASSERT_TRUE(WriteManifest(*dir_ / "db", manifest).ok());
    // Frames 0..9 of view kView turning 0.03 rad a frame: frame 3 missing, frame 5 not a PNG.
    fs::create_directories(*dir_ / "frames");
    for (int t = 0; t < 10; ++t) {
      char name[32];
      std::snprintf(name, sizeof(name), "frame_%04d.png", 100 + t);
      if (t == 3) continue;
      if (t == 5) {
        std::ofstream(*dir_ / "frames" / name) << "\x89PNG but not really";
        continue;
      }
      ASSERT_TRUE(cv::imwrite((*dir_ / "frames" / name).string(), Draw(0.03 * t, false)));
    }
  }
  static void TearDownTestSuite() { delete dir_; }

  // View kView turned by `angle`, 1.2 px per normalised px, in a 256 x 256 frame: an edge image,
  // or a photo-like one (a skin-coloured hull with darker strokes).
  static cv::Mat Draw(double angle, bool photo) {
    const auto pts = testing::SyntheticEdgeSet(kView, 300);
    cv::Mat edges = cv::Mat::zeros(256, 256, CV_8U);
    const double c = std::cos(angle), s = std::sin(angle);
    for (const PointQ& q : pts) {
      const double x = PointQToPx(q.x), y = PointQToPx(q.y);
      edges.at<uint8_t>(static_cast<int>(std::lround(128 + 1.1 * (s * x + c * y))),
                        static_cast<int>(std::lround(128 + 1.1 * (c * x - s * y)))) = 255;
    }
    if (!photo) return edges;
    std::vector<cv::Point> all, hull;
    cv::findNonZero(edges, all);
    cv::convexHull(all, hull);
    cv::Mat img(edges.size(), CV_8UC3, cv::Scalar(150, 110, 80));
    cv::fillConvexPoly(img, hull, cv::Scalar(120, 150, 210));
    cv::Mat thick;
    cv::dilate(edges, thick, cv::Mat::ones(5, 5, CV_8U));
    img.setTo(cv::Scalar(70, 95, 150), thick);
    return img;
  }

  static fs::path* dir_;
};
fs::path* TrackCli::dir_ = nullptr;

TEST_F(TrackCli, FolderOfFramesGivesOneValidLinePerFrameAndGoesOnPastBadOnes) {
  const std::string db = (*dir_ / "db").string();
  const std::string frames = (*dir_ / "frames").string();
  // This synthetic set's best D_c swings by ~2 px as the view turns between two stored rolls.
  const CliRun r = Handdb(db + " " + frames + " --top 5 --threads 2 --quiet --refind-margin 2");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::vector<json> lines = Lines(r.out);
  ASSERT_EQ(lines.size(), 10u) << r.out;
  for (size_t t = 0; t < lines.size(); ++t) {
    const json& f = lines[t];
    const Status valid = ValidateJson(f, "track_frame.schema.json", "frame");
    EXPECT_TRUE(valid.ok()) << valid.ToString();
    EXPECT_EQ(f["frame"], t);
    EXPECT_NEAR(f["time_s"].get<double>(), t / 30.0, 1e-9);
    if (t == 3 || t == 5) {
      EXPECT_EQ(f["found"], "none") << t;
      EXPECT_FALSE(f.contains("pose"));
      EXPECT_EQ(f["code"], t == 3 ? "kNotFound" : "kBadImage");
      continue;
    }
    EXPECT_EQ(f["found"], t == 0 ? "full" : "local") << t;
    ASSERT_TRUE(f.contains("pose")) << t;
    EXPECT_EQ(f["pose"]["view_id"], kView) << t;
    EXPECT_EQ(f["pose"]["keypoints_image_px"].size(), 21u);
    EXPECT_EQ(f["matches"].size(), 5u);
  }
  EXPECT_LT(lines[1]["search"]["pairs"].get<uint64_t>(),
            lines[0]["search"]["pairs"].get<uint64_t>() / 4);
  // The bad frames' lines are on stderr too, one each, even with --quiet off.
  const CliRun loud = Handdb(db + " " + frames + " --top 5 --smooth offline");
  ASSERT_EQ(loud.code, 0) << loud.err;
  EXPECT_NE(loud.err.find("frame 3: frame 3 is missing"), std::string::npos) << loud.err;
  EXPECT_NE(loud.err.find("frame_0105.png"), std::string::npos) << loud.err;
  EXPECT_NE(loud.err.find("10 frames"), std::string::npos) << loud.err;
}

TEST_F(TrackCli, OutFileAndOverlayFrames) {
  const std::string db = (*dir_ / "db").string();
  const fs::path out = *dir_ / "track.jsonl";
  const fs::path overlay = *dir_ / "overlay";
  const CliRun r = Handdb(db + " " + (*dir_ / "frames").string() + " --quiet --smooth off --out " +
                          out.string() + " --overlay " + overlay.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(r.out.empty());
  std::ifstream in(out);
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_EQ(Lines(text.str()).size(), 10u);
  const cv::Mat first = cv::imread((overlay / "frame-000000.png").string());
  ASSERT_FALSE(first.empty());
  EXPECT_EQ(first.cols, 256);
  // The skeleton is drawn in colour over the grey edge image.
  cv::Mat hsv;
  cv::cvtColor(first, hsv, cv::COLOR_BGR2HSV);
  std::vector<cv::Mat> channels;
  cv::split(hsv, channels);
  EXPECT_GT(cv::countNonZero(channels[1] > 100), 50);
  EXPECT_FALSE(fs::exists(overlay / "frame-000003.png"));  // missing: nothing to draw on
}

// A video file goes through the video plugin: every frame is read and tracked.
TEST_F(TrackCli, VideoThroughThePlugin) {
  const fs::path video = *dir_ / "hand.avi";
  {
    cv::VideoWriter writer(video.string(),
                           cv::CAP_FFMPEG,
                           cv::VideoWriter::fourcc('F', 'F', 'V', '1'),
                           25,
                           cv::Size(256, 256));
    if (!writer.isOpened()) GTEST_SKIP() << "no FFV1 encoder in this OpenCV";
    for (int t = 0; t < 8; ++t) writer.write(Draw(0.03 * t, true));
  }
  const CliRun r = Handdb((*dir_ / "db").string() + " " + video.string() + " --quiet --top 3");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::vector<json> lines = Lines(r.out);
  ASSERT_EQ(lines.size(), 8u) << r.out << r.err;
  int found = 0;
  for (const json& f : lines) {
    EXPECT_TRUE(ValidateJson(f, "track_frame.schema.json", "frame").ok());
    EXPECT_EQ(f["source"].get<std::string>().rfind(video.string() + "#", 0), 0u);
    if (f["found"] != "none" && f["pose"]["view_id"] == kView) ++found;
  }
  EXPECT_GE(found, 6);
  EXPECT_NEAR(lines[4]["time_s"].get<double>(), 4 / 25.0, 1e-3);
  // Without the plugin: one line naming it, exit 1.
  const CliRun none = Handdb((*dir_ / "db").string() + " " + video.string(),
                             "HANDDB_VIDEOIO_PLUGIN=" + (*dir_ / "no-plugin.so").string());
  EXPECT_EQ(none.code, 1);
  EXPECT_NE(none.err.find("libhanddb_videoio.so"), std::string::npos) << none.err;
}

TEST_F(TrackCli, ErrorsAndUsage) {
  const std::string db = (*dir_ / "db").string();
  CliRun r = Handdb(db + " " + (*dir_ / "nothing-here").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("nothing-here: no such video or folder"), std::string::npos) << r.err;
  r = Handdb((*dir_ / "no-db").string() + " " + (*dir_ / "frames").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  r = Handdb(db + " " + (*dir_ / "frames").string() + " --smooth sometimes");
  EXPECT_EQ(r.code, 2);
  r = Handdb(db + " " + (*dir_ / "db").string());  // a folder without frames
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("no frames"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace handdb
