// The TFLite interpreter and the hand landmark network, on the installed model
// (scripts/deps.sh --asset) and the real photos of tests/data/photos: hostile model files are
// errors, and the joints the network finds are where the hand's joints are.
#include "photo/hand_landmarks.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "base/testing.h"
#include "nn/tflite.h"
#include "photo/image_edges.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

// PointQ has no ==: the same points, in the same order.
bool SamePoints(const std::vector<PointQ>& a, const std::vector<PointQ>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].x != b[i].x || a[i].y != b[i].y) return false;
  }
  return true;
}

fs::path SourceDir() {
  const char* env = std::getenv("HANDDB_SOURCE_DIR");
  return env != nullptr ? fs::path(env) : fs::path(".");
}

fs::path Photo(const std::string& shape, const std::string& file) {
  return SourceDir() / "tests" / "data" / "photos" / "asl-digits" / shape / file;
}

// The landmarks were found in `crop`.
void ExpectFoundIn(const HandLandmarks& l, const LandmarkCrop& crop) {
  EXPECT_NEAR(l.crop.centre.x, crop.centre.x, 1e-3);
  EXPECT_NEAR(l.crop.centre.y, crop.centre.y, 1e-3);
  EXPECT_NEAR(l.crop.side, crop.side, 1e-3);
  EXPECT_NEAR(l.crop.angle_deg, crop.angle_deg, 1e-3);
}

// Two runs found the same hand: no joint moved by `max_px` or more.
void ExpectSameHand(const HandLandmarks& a, const HandLandmarks& b, double max_px) {
  for (int k = 0; k < kNumLandmarks; ++k) {
    EXPECT_LT(std::hypot(a.image_px[k].x - b.image_px[k].x, a.image_px[k].y - b.image_px[k].y),
              max_px)
        << k;
  }
}

// The installed model; the README's test command installs it, so its absence is a failure.
fs::path Model() {
  const fs::path model = HandLandmarker::DefaultModelPath();
  THROW_CHECK_MSG(fs::exists(model), model.string() << " is missing: run scripts/deps.sh --asset");
  return model;
}

TEST(TfliteModelTest, LoadsTheLandmarkModel) {
  auto m = TfliteModel::Load(Model());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->input_shape(), (std::vector<int>{1, 224, 224, 3}));
  const std::vector<size_t> sizes = m->output_sizes();
  ASSERT_GE(sizes.size(), 2u);
  EXPECT_EQ(sizes[0], 63u);
  EXPECT_EQ(sizes[1], 1u);
  std::printf("landmark model: %.3g multiply-adds per run\n",
              static_cast<double>(m->multiply_adds()));
  EXPECT_GT(m->multiply_adds(), 1e8);
  EXPECT_LT(m->multiply_adds(), 1e10);
  // A grey picture is no hand: the presence output (a logistic) is low, and finite.
  std::vector<float> grey(224 * 224 * 3, 0.5f);
  const auto out = m->Run(grey);
  ASSERT_EQ(out.size(), sizes.size());
  EXPECT_LT(out[1][0], 0.5f);
  for (float v : out[0]) EXPECT_TRUE(std::isfinite(v));
  // A workspace kept between calls gives the same numbers.
  auto ws = m->NewWorkspace();
  const auto again = m->Run(grey, ws.get());
  const auto third = m->Run(grey, ws.get());
  EXPECT_EQ(again, out);
  EXPECT_EQ(third, out);
}

TEST(TfliteModelTest, BrokenFilesAreErrorsNamingTheFile) {
  const fs::path dir = testing::TempDir("tflite");
  EXPECT_EQ(TfliteModel::Load(dir / "missing.tflite").status().code(), StatusCode::kNotFound);
  testing::WriteBytes(dir / "text.tflite", {'h', 'e', 'l', 'l', 'o', ' ', 'w', 'o', 'r', 'l', 'd'});
  auto text = TfliteModel::Load(dir / "text.tflite");
  ASSERT_FALSE(text.ok());
  EXPECT_EQ(text.status().code(), StatusCode::kBadMagic);
  EXPECT_NE(text.status().message().find("text.tflite"), std::string::npos);

  // Every truncation of the real model is refused (a flatbuffer's offsets point past the end),
  // never read out of bounds (the sanitizer build runs this too).
  const std::vector<uint8_t> bytes = testing::ReadBytes(Model());
  std::mt19937 rng(7);
  std::vector<size_t> cuts = {8, 12, 64, 4096, bytes.size() / 2, bytes.size() - 1};
  for (int k = 0; k < 6; ++k) cuts.push_back(8 + rng() % (bytes.size() - 8));
  for (size_t cut : cuts) {
    const fs::path p = dir / "cut.tflite";
    testing::WriteBytes(p, std::vector<uint8_t>(bytes.begin(), bytes.begin() + cut));
    auto m = TfliteModel::Load(p);
    EXPECT_FALSE(m.ok()) << "cut at " << cut;
    if (!m.ok()) {
      EXPECT_NE(m.status().message().find("cut.tflite"), std::string::npos)
          << m.status().ToString();
    }
  }
  // Corrupted bytes in the tables (the model's last 64 KiB: the flatbuffer's vtables, tensors
  // and operators follow its weights): loading fails cleanly, or the graph still checks out and
  // runs within its own buffers.
  std::vector<float> grey(224 * 224 * 3, 0.5f);
  int ran = 0;
  for (int k = 0; k < 40; ++k) {
    std::vector<uint8_t> bad = bytes;
    const size_t span = std::min<size_t>(65536, bad.size() - 8);
    for (int j = 0; j < 4; ++j)
      bad[bad.size() - 1 - rng() % span] ^= static_cast<uint8_t>(1 + rng() % 255);
    const fs::path p = dir / "flipped.tflite";
    testing::WriteBytes(p, bad);
    auto m = TfliteModel::Load(p);
    if (m.ok() && ran < 3 && m->input_shape() == std::vector<int>{1, 224, 224, 3}) {
      m->Run(grey);
      ++ran;
    }
  }
  fs::remove_all(dir);
}

TEST(HandLandmarkerTest, RefusesAModelThatIsNotALandmarkModel) {
  const fs::path dir = testing::TempDir("landmarker");
  auto m = HandLandmarker::Open(dir / "none.tflite");
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kNotFound);
  fs::remove_all(dir);
}

// The joints on real photos: the network sees the hand the photo path segmented, and maps the
// joints back to the picture's pixels.
TEST(HandLandmarkerTest, FindsTheJointsOfRealPhotos) {
  auto landmarker = HandLandmarker::Open(Model());
  ASSERT_TRUE(landmarker.ok()) << landmarker.status().ToString();
  PictureOptions options;
  options.landmarker = *landmarker;
  // asl-1: the index finger points up, the others are folded; asl-5: an open hand.
  for (const auto& [shape, file] : std::vector<std::pair<std::string, std::string>>{
           {"asl-1", "IMG_1170.JPG"}, {"asl-5", "IMG_1174.JPG"}}) {
    SCOPED_TRACE(shape);
    auto picture = ReadPicture(Photo(shape, file), options);
    ASSERT_TRUE(picture.ok()) << picture.status().ToString();
    ASSERT_TRUE(picture->landmarks.has_value());
    const HandLandmarks& l = *picture->landmarks;
    const QueryEdges* q = &picture->edges;
    // The network runs beside the edge extraction: the edges are those of LoadQueryEdges.
    auto edges = LoadQueryEdges(Photo(shape, file), options.edges);
    ASSERT_TRUE(edges.ok());
    EXPECT_TRUE(SamePoints(edges->points, q->points));
    EXPECT_EQ(edges->centre_x, q->centre_x);
    EXPECT_EQ(edges->centre_y, q->centre_y);
    EXPECT_EQ(edges->scale, q->scale);
    EXPECT_GT(l.presence, 0.9f);
    // Two passes: the first on the segmentation's crop, the answer on the crop its joints give.
    PictureOptions once = options;
    once.landmark_passes = 1;
    auto first = ReadPicture(Photo(shape, file), once);
    ASSERT_TRUE(first.ok() && first->landmarks.has_value());
    EXPECT_NEAR(first->landmarks->crop.side, 1.5 * q->diameter_px, 1e-3);
    EXPECT_GT(first->landmarks->presence, 0.9f);
    ExpectFoundIn(l, CropAroundLandmarks(*first->landmarks));
    // The two runs find the same hand: no joint moves by more than a tenth of its diameter.
    ExpectSameHand(*first->landmarks, l, 0.1 * q->diameter_px);
    // Every joint in the picture (the wrist may lie a little past the border the arm leaves
    // by), near the hand (within its diameter of its centre).
    const double margin = 0.1 * q->diameter_px;
    for (const Point2f& p : l.image_px) {
      EXPECT_GE(p.x, -margin);
      EXPECT_LE(p.x, q->width + margin);
      EXPECT_GE(p.y, -margin);
      EXPECT_LE(p.y, q->height + margin);
      EXPECT_LT(std::hypot(p.x - q->centre_x, p.y - q->centre_y), q->diameter_px);
    }
    // The arm leaves at the bottom: the wrist is below every fingertip.
    for (int tip : {4, 8, 12, 16, 20}) EXPECT_GT(l.image_px[0].y, l.image_px[tip].y) << tip;
    if (shape == "asl-1") {
      // The raised index tip is the highest joint, well above the folded middle finger's tip.
      for (int k = 0; k < kNumLandmarks; ++k) {
        if (k != 8) {
          EXPECT_LT(l.image_px[8].y, l.image_px[k].y) << k;
        }
      }
      EXPECT_LT(l.image_px[8].y + 0.2 * q->diameter_px, l.image_px[12].y);
    } else {
      // Open hand: each fingertip lies further from the wrist than its own base joint.
      for (int f = 0; f < 5; ++f) {
        const Point2f& w = l.image_px[0];
        const Point2f& base = l.image_px[1 + 4 * f];
        const Point2f& tip = l.image_px[4 + 4 * f];
        EXPECT_GT(std::hypot(tip.x - w.x, tip.y - w.y), std::hypot(base.x - w.x, base.y - w.y))
            << "finger " << f;
      }
    }
  }
}

// A video's frame: the network runs once, on the crop around the last frame's joints, while it
// finds a hand there; a crop without the hand starts the frame over from the segmentation.
TEST(HandLandmarkerTest, ATrackedCropRunsTheNetworkOnceWhileItHoldsTheHand) {
  auto landmarker = HandLandmarker::Open(Model());
  ASSERT_TRUE(landmarker.ok()) << landmarker.status().ToString();
  PictureOptions options;
  options.landmarker = *landmarker;
  const fs::path photo = Photo("asl-5", "IMG_1174.JPG");
  auto alone = ReadPicture(photo, options);
  ASSERT_TRUE(alone.ok() && alone->landmarks.has_value());

  PictureOptions tracked = options;
  tracked.landmark_start = CropAroundLandmarks(*alone->landmarks);
  auto next = ReadPicture(photo, tracked);
  ASSERT_TRUE(next.ok() && next->landmarks.has_value());
  const HandLandmarks& l = *next->landmarks;
  EXPECT_GE(l.presence, kTrackedCropPresence);
  ExpectFoundIn(l, *tracked.landmark_start);
  ExpectSameHand(*alone->landmarks, l, 0.1 * alone->edges.diameter_px);

  // A crop of the picture's corner holds no hand: the frame's joints are the picture's alone.
  tracked.landmark_start = LandmarkCrop{{2, 2}, 8, 0};
  auto lost = ReadPicture(photo, tracked);
  ASSERT_TRUE(lost.ok() && lost->landmarks.has_value());
  EXPECT_EQ(lost->landmarks->crop.side, alone->landmarks->crop.side);
  EXPECT_EQ(lost->landmarks->image_px[12].x, alone->landmarks->image_px[12].x);
  EXPECT_EQ(lost->landmarks->presence, alone->landmarks->presence);
}

// MediaPipe's crop around a hand's joints: turned so the hand points up, centred on the box of
// the palm's and digits' first joints, a tenth of the box towards the fingers, twice it wide.
// Turning and moving the joints turns and moves the crop with them.
TEST(CropAroundLandmarksTest, FollowsTheHandsTurnAndPlace) {
  HandLandmarks up;  // a hand pointing up the picture, wrist at (100, 200)
  up.image_px[0] = {100, 200};
  for (int f = 0; f < 5; ++f) {
    const float x = 70 + 15.0f * f;  // thumb at the left, little finger at the right
    for (int j = 0; j < 4; ++j) up.image_px[1 + 4 * f + j] = {x, 140 - 20.0f * j};
  }
  const LandmarkCrop c = CropAroundLandmarks(up);
  EXPECT_NEAR(c.angle_deg, 0, 1e-4);
  // The box of joints 0, 1-3, 5-6, 9-10, 13-14, 17-18: x 70..130, y 100..200 (the thumb's
  // third joint at 100); its longer side 100, its centre (100, 150) moved up by 10.
  EXPECT_NEAR(c.side, 200, 1e-3);
  EXPECT_NEAR(c.centre.x, 100, 1e-3);
  EXPECT_NEAR(c.centre.y, 140, 1e-3);

  const double turn = 30 * M_PI / 180;  // clockwise in the picture (y down)
  const double cs = std::cos(turn), sn = std::sin(turn);
  auto move = [&](Point2f p) {
    const double x = p.x - 100, y = p.y - 200;
    return Point2f{static_cast<float>(cs * x - sn * y + 400),
                   static_cast<float>(sn * x + cs * y + 50)};
  };
  HandLandmarks turned = up;
  for (Point2f& p : turned.image_px) p = move(p);
  const LandmarkCrop t = CropAroundLandmarks(turned);
  EXPECT_NEAR(t.angle_deg, 30, 1e-3);
  EXPECT_NEAR(t.side, 200, 1e-2);
  const Point2f centre = move(c.centre);
  EXPECT_NEAR(t.centre.x, centre.x, 1e-2);
  EXPECT_NEAR(t.centre.y, centre.y, 1e-2);
}

// No landmarker: no landmarks (edge images and label EXRs never get any).
TEST(HandLandmarkerTest, OnlyPhotosWithALandmarkerGetLandmarks) {
  auto q = ReadPicture(Photo("asl-1", "IMG_1170.JPG"), PictureOptions{});
  ASSERT_TRUE(q.ok()) << q.status().ToString();
  EXPECT_FALSE(q->landmarks.has_value());
}

}  // namespace
}  // namespace handdb
