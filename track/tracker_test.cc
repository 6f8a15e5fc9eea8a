#include "track/tracker.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "base/testing.h"
#include "photo/hand_landmarks.h"
#include "photo/image_edges.h"
#include "query/search_testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

constexpr uint32_t kViews = 24;
constexpr uint32_t kRolls = 64;  // 5.6 degrees apart
constexpr size_t kPoints = 300;
constexpr uint32_t kView = 5;  // the view the frames show

std::shared_ptr<const Database> TestDatabase() {
  static const auto db = std::make_shared<const Database>(
      testing::SyntheticDatabase(kViews, kPoints, kRolls, /*views_per_shape=*/4));
  return db;
}

// View kView turned by `angle` (radians), drawn at 1.2 px per normalised px into a 320 x 320
// edge image.
cv::Mat Draw(double angle) {
  const auto pts = testing::SyntheticEdgeSet(kView, kPoints);
  cv::Mat edges = cv::Mat::zeros(320, 320, CV_8U);
  const double c = std::cos(angle), s = std::sin(angle);
  for (const PointQ& q : pts) {
    const double x = PointQToPx(q.x), y = PointQToPx(q.y);
    edges.at<uint8_t>(static_cast<int>(std::lround(160 + 1.2 * (s * x + c * y))),
                      static_cast<int>(std::lround(160 + 1.2 * (c * x - s * y)))) = 255;
  }
  return edges;
}

// Frames f000..f011 of the view turning 0.03 rad a frame; f004 missing, f006 not a picture,
// f008 empty (no hand), f009 a repeat of f007's picture.
fs::path WriteFrames(const fs::path& dir) {
  fs::create_directories(dir);
  for (int t = 0; t < 12; ++t) {
    char name[32];
    std::snprintf(name, sizeof(name), "f%03d.png", t);
    if (t == 4) continue;
    if (t == 6) {
      std::ofstream(dir / name) << "not a png";
      continue;
    }
    const cv::Mat frame = t == 8 ? cv::Mat::zeros(320, 320, CV_8U) : Draw(0.03 * (t == 9 ? 7 : t));
    EXPECT_TRUE(cv::imwrite((dir / name).string(), frame));
  }
  return dir;
}

std::vector<TrackFrame> Track(const fs::path& dir, const TrackOptions& options) {
  const Searcher searcher(TestDatabase());
  auto source = OpenFrameFolder(dir);
  EXPECT_TRUE(source.ok()) << source.status().ToString();
  std::vector<TrackFrame> frames;
  auto summary = TrackFrames(searcher, **source, options, [&](const TrackFrame& f) {
    frames.push_back(f);
    return Status::Ok();
  });
  EXPECT_TRUE(summary.ok()) << summary.status().ToString();
  if (summary.ok()) {
    EXPECT_EQ(summary->frames, static_cast<int64_t>(frames.size()));
  }
  return frames;
}

TrackOptions Options() {
  TrackOptions o;
  // This synthetic set's best D_c swings from 0.7 to 3 px as the view turns between two stored
  // rolls.
  o.refind_margin_px = 2;
  o.picture.search.top_k = 5;
  o.picture.search.hand = Hand::kEither;
  return o;
}

TEST(TrackFrames, LocalSearchFollowsTheHandAndBadFramesAreGaps) {
  const fs::path dir = WriteFrames(testing::TempDir("track") / "frames");
  const std::vector<TrackFrame> frames = Track(dir, Options());
  ASSERT_EQ(frames.size(), 12u);
  const std::vector<FoundBy> want = {FoundBy::kFull,
                                     FoundBy::kLocal,
                                     FoundBy::kLocal,
                                     FoundBy::kLocal,
                                     FoundBy::kNone,   // missing
                                     FoundBy::kLocal,  // the search still knows frame 3's answer
                                     FoundBy::kNone,   // not a picture
                                     FoundBy::kLocal,
                                     FoundBy::kNone,  // no hand: lost
                                     FoundBy::kFull,  // found again by a full search
                                     FoundBy::kLocal,
                                     FoundBy::kLocal};
  uint64_t full_pairs = 0, local_pairs = 0;
  for (size_t t = 0; t < frames.size(); ++t) {
    const TrackFrame& f = frames[t];
    EXPECT_EQ(f.index, static_cast<int64_t>(t));
    EXPECT_NEAR(f.time_s, t / 30.0, 1e-9);
    EXPECT_EQ(f.found, want[t]) << "frame " << t << ": " << FoundByName(f.found) << " "
                                << f.error.ToString();
    if (f.found == FoundBy::kNone) {
      EXPECT_FALSE(f.error.ok());
      EXPECT_FALSE(f.has_pose);
      continue;
    }
    ASSERT_GE(f.chosen, 0);
    EXPECT_EQ(f.matches[f.chosen].view_id, kView) << "frame " << t;
    EXPECT_TRUE(f.has_pose);
    (f.found == FoundBy::kFull ? full_pairs : local_pairs) = f.pairs_searched;
  }
  EXPECT_EQ(frames[4].error.code(), StatusCode::kNotFound);
  EXPECT_EQ(frames[6].error.code(), StatusCode::kBadImage);
  EXPECT_GT(full_pairs, 4 * local_pairs);
}

// Carried: a frame whose edges are the previous frame's keeps its matches without a search.
TEST(TrackFrames, ARepeatedFrameCarriesTheAnswer) {
  const fs::path dir = testing::TempDir("track") / "repeat";
  fs::create_directories(dir);
  for (int t = 0; t < 3; ++t) {
    ASSERT_TRUE(cv::imwrite((dir / ("r" + std::to_string(t) + ".png")).string(), Draw(0.1)));
  }
  const auto frames = Track(dir, Options());
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[0].found, FoundBy::kFull);
  EXPECT_EQ(frames[1].found, FoundBy::kCarried);
  EXPECT_EQ(frames[1].pairs_searched, 0u);
  EXPECT_EQ(frames[2].matches.front().distance, frames[0].matches.front().distance);
}

// Every frame searched in full, or smoothed offline: the same answers on this steady sequence.
TEST(TrackFrames, FullSearchEveryFrameAndOfflineSmoothingAgree) {
  const fs::path dir = WriteFrames(testing::TempDir("track") / "frames");
  TrackOptions full = Options();
  full.local_search = false;
  TrackOptions offline = Options();
  offline.smoothing = Smoothing::kOffline;
  offline.full_every = 3;
  const auto a = Track(dir, full);
  const auto b = Track(dir, offline);
  ASSERT_EQ(a.size(), b.size());
  for (size_t t = 0; t < a.size(); ++t) {
    EXPECT_EQ(a[t].has_pose, b[t].has_pose) << t;
    if (!a[t].has_pose) continue;
    EXPECT_EQ(a[t].found, FoundBy::kFull) << t;
    EXPECT_EQ(a[t].matches[a[t].chosen].view_id, b[t].matches[b[t].chosen].view_id) << t;
    EXPECT_EQ(a[t].matches[a[t].chosen].roll, b[t].matches[b[t].chosen].roll) << t;
  }
  // full_every 3: no more than two local searches in a row.
  int run = 0;
  for (const TrackFrame& f : b) {
    run = f.found == FoundBy::kLocal ? run + 1 : 0;
    EXPECT_LT(run, 3) << f.index;
  }
}

// A real photo (tests/data/photos) and the same picture 3 px to the right: with landmark
// tracking the second frame's network runs on the crop around the first frame's joints; without,
// each frame's landmarks are its picture's alone.
TEST(TrackFrames, TheLandmarkNetworkLooksWhereTheLastFramesJointsWere) {
  const char* source_dir = std::getenv("HANDDB_SOURCE_DIR");
  const fs::path root = source_dir != nullptr ? fs::path(source_dir) : fs::path(".");
  auto landmarker = HandLandmarker::Open(HandLandmarker::DefaultModelPath());
  ASSERT_TRUE(landmarker.ok()) << landmarker.status().ToString();
  const cv::Mat photo = cv::imread(
      (root / "tests/data/photos/asl-digits/asl-5/IMG_1174.JPG").string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(photo.empty());
  const fs::path dir = testing::TempDir("track_landmarks");
  cv::Mat moved;
  cv::warpAffine(photo,
                 moved,
                 cv::Matx23d(1, 0, 3, 0, 1, 0),
                 photo.size(),
                 cv::INTER_NEAREST,
                 cv::BORDER_REPLICATE);
  ASSERT_TRUE(cv::imwrite((dir / "f000.png").string(), photo));
  ASSERT_TRUE(cv::imwrite((dir / "f001.png").string(), moved));

  TrackOptions options = Options();
  options.picture.picture.landmarker = *landmarker;
  const std::vector<TrackFrame> tracked = Track(dir, options);
  options.landmark_tracking = false;
  const std::vector<TrackFrame> alone = Track(dir, options);
  ASSERT_EQ(tracked.size(), 2u);
  ASSERT_EQ(alone.size(), 2u);
  for (const auto* frames : {&tracked, &alone}) {
    for (const TrackFrame& f : *frames) {
      ASSERT_TRUE(f.evidence.has_value() && f.evidence->landmarks.has_value()) << f.index;
    }
  }
  const HandLandmarks& first = *tracked[0].evidence->landmarks;
  const HandLandmarks& second = *tracked[1].evidence->landmarks;
  const LandmarkCrop crop = CropAroundLandmarks(first);
  EXPECT_NEAR(second.crop.centre.x, crop.centre.x, 1e-3);
  EXPECT_NEAR(second.crop.centre.y, crop.centre.y, 1e-3);
  EXPECT_NEAR(second.crop.side, crop.side, 1e-3);
  // The first frame has no frame before it: both ways it is the picture's alone.
  EXPECT_EQ(first.crop.side, alone[0].evidence->landmarks->crop.side);
  auto picture = ReadPicture(dir / "f001.png", options.picture.picture);
  ASSERT_TRUE(picture.ok() && picture->landmarks.has_value());
  EXPECT_EQ(alone[1].evidence->landmarks->crop.side, picture->landmarks->crop.side);
  EXPECT_EQ(alone[1].evidence->landmarks->image_px[8].x, picture->landmarks->image_px[8].x);
  EXPECT_NE(alone[1].evidence->landmarks->crop.side, second.crop.side);
  fs::remove_all(dir);
}

TEST(TrackOptions, Check) {
  EXPECT_TRUE(TrackOptions{}.Check());
  TrackOptions o;
  o.refind_ratio = 0.5;
  EXPECT_FALSE(o.Check());
  o = {};
  o.window = 0;
  EXPECT_FALSE(o.Check());
  EXPECT_FALSE(ParseSmoothing("sometimes").ok());
  EXPECT_EQ(*ParseSmoothing("offline"), Smoothing::kOffline);
}

}  // namespace
}  // namespace handdb
