// A picture through the whole query: edges and normalisation (photo/), the search (query/),
// keypoints mapped back into the picture, and the contact sheet (pose/sheet.h).
#include "pose/picture_search.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "edges/edges.h"
#include "edges/exr_io.h"
#include "edges/normalise.h"
#include "edges/synthetic_hand.h"
#include "photo/image_edges.h"
#include "photo/photo_testing.h"
#include "pose/landmark_rank.h"
#include "pose/sheet.h"
#include "query/searcher.h"

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

using ImageEdgesTest = SyntheticPictureTest;

TEST_F(ImageEdgesTest, KeypointsInTheInputImageForRightAndLeftHands) {
  std::vector<ViewLabel> db_labels;
  std::vector<std::vector<PointQ>> db_points;
  for (int i = 0; i < 8; ++i) {
    const SyntheticHand h = Hand(0.0, 0.06 * i);
    const fs::path exr = dir_ / ("v" + std::to_string(i) + ".exr");
    ASSERT_TRUE(WriteLabelExr(exr, h.image).ok());
    auto q = LoadQueryEdges(exr, ImageEdgeOptions{});
    ASSERT_TRUE(q.ok());
    ViewLabel l;
    l.render_id = i;
    l.shape_id = 0;
    for (int k = 0; k < kNumKeypoints; ++k) {
      l.keypoints[k] = {static_cast<float>((h.keypoints_px[k][0] - q->centre_x) * q->scale),
                        static_cast<float>((h.keypoints_px[k][1] - q->centre_y) * q->scale),
                        0.0f};
    }
    db_labels.push_back(l);
    db_points.push_back(q->points);
  }
  // 16 rolls of 22.5 degrees: the photographed hand is turned by 3 of them.
  const auto db = std::make_shared<const Database>(
      Database::FromMemory(db_labels, db_points, 16, {"synthetic"}));
  const Searcher searcher(db);
  const SyntheticHand target = Hand(3 * 2 * M_PI / 16, 0.06 * 5);
  LabelImage flipped = target.image;
  for (int y = 0; y < flipped.height; ++y) {
    for (int x = 0; x < flipped.width; ++x) {
      const size_t from = static_cast<size_t>(y) * flipped.width + (flipped.width - 1 - x);
      flipped.labels[static_cast<size_t>(y) * flipped.width + x] = target.image.labels[from];
      if (flipped.has_depth()) {
        flipped.depth[static_cast<size_t>(y) * flipped.width + x] = target.image.depth[from];
      }
    }
  }
  for (const bool left : {false, true}) {
    const fs::path png = WritePhoto(left ? flipped : target.image, left ? "l.png" : "r.png", 5);
    auto photo = LoadQueryEdges(png, ImageEdgeOptions{});
    ASSERT_TRUE(photo.ok());
    SearchOptions o;
    o.top_k = 2;
    o.num_threads = 2;
    o.hand = Hand::kEither;
    auto res = searcher.Search(photo->points_px(), o);
    ASSERT_TRUE(res.ok());
    const Match& m = (*res)[0];
    EXPECT_EQ(m.view_id, 5u) << "left " << left;
    EXPECT_EQ(m.roll, 3u) << "left " << left;
    EXPECT_EQ(m.hand, left ? Hand::kLeft : Hand::kRight);
    double worst = 0;
    for (int k = 0; k < kNumKeypoints; ++k) {
      const Point2f p =
          photo->ImageFromNormalised({m.label.keypoints[k][0], m.label.keypoints[k][1]});
      // Mirroring the picture about its vertical centre line: u -> width - u.
      const double tx =
          left ? target.image.width - target.keypoints_px[k][0] : target.keypoints_px[k][0];
      const double ty = target.keypoints_px[k][1];
      worst = std::max(worst, std::hypot(p.x - tx, p.y - ty));
    }
    EXPECT_LT(worst, 1.0) << "left " << left;
  }
}

TEST_F(ImageEdgesTest, PhotoOfADatabaseViewFindsIt) {
  // A small database of label-path views at several in-plane angles and bends; the photo of one
  // of them must come back first.
  std::vector<ViewLabel> db_labels;
  std::vector<std::vector<PointQ>> db_points;
  for (int i = 0; i < 12; ++i) {
    const SyntheticHand h = Hand(0.5 * i, 0.05 * (i % 4));
    const fs::path exr = dir_ / ("v" + std::to_string(i) + ".exr");
    ASSERT_TRUE(WriteLabelExr(exr, h.image).ok());
    auto q = LoadQueryEdges(exr, ImageEdgeOptions{});
    ASSERT_TRUE(q.ok());
    ViewLabel l;
    l.render_id = i;
    l.shape_id = 0;
    db_labels.push_back(l);
    db_points.push_back(q->points);
  }
  const auto db = std::make_shared<const Database>(
      Database::FromMemory(db_labels, db_points, 8, {"synthetic"}));
  const Searcher searcher(db);
  const SyntheticHand target = Hand(0.5 * 7, 0.05 * 3);
  auto photo = LoadQueryEdges(WritePhoto(target.image, "q.png", 9), ImageEdgeOptions{});
  ASSERT_TRUE(photo.ok());
  SearchOptions o;
  o.top_k = 3;
  o.num_threads = 2;
  auto res = searcher.Search(photo->points_px(), o);
  ASSERT_TRUE(res.ok());
  EXPECT_EQ((*res)[0].view_id, 7u);
  EXPECT_EQ((*res)[0].roll, 0u);
  EXPECT_EQ((*res)[0].shape_name, "synthetic");

  // And the contact sheet is a readable PNG with input, query and match tiles.
  std::vector<SheetTile> tiles;
  for (const Match& m : *res) {
    SheetTile t;
    t.caption = "#" + std::to_string(tiles.size() + 1);
    for (const PointQ& p : db->points(m.view_id)) t.points.push_back(p);
    tiles.push_back(t);
  }
  PictureEvidence evidence;
  evidence.edges = *photo;
  const fs::path sheet = dir_ / "sheet.png";
  ASSERT_TRUE(
      WriteContactSheet(sheet, dir_ / "q.png", evidence, tiles, ContactSheetOptions{}).ok());
  const cv::Mat img = cv::imread(sheet.string());
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, 4 * 240 + 5 * 4);  // 5 tiles in 4 columns -> 2 rows
  EXPECT_EQ(img.rows, 2 * (240 + 22) + 3 * 4);

  // With the top match's skeleton (here the true keypoints) drawn over the input tile.
  std::vector<Point2f> skeleton;
  for (const auto& k : target.keypoints_px) {
    skeleton.push_back({static_cast<float>(k[0]), static_cast<float>(k[1])});
  }
  const fs::path with = dir_ / "sheet-skeleton.png";
  ASSERT_TRUE(
      WriteContactSheet(with, dir_ / "q.png", evidence, tiles, ContactSheetOptions{}, skeleton)
          .ok());
  const auto amber_pixels = [](const cv::Mat& sheet_img) {
    const cv::Mat input_tile = sheet_img(cv::Rect(4, 4 + 22, 240, 240));
    int n = 0;
    for (int y = 0; y < input_tile.rows; ++y) {
      for (int x = 0; x < input_tile.cols; ++x) {
        const cv::Vec3b c = input_tile.at<cv::Vec3b>(y, x);
        n += c[0] < 80 && c[1] > 150 && c[2] > 200;  // the bones' amber (BGR 0, 215, 255)
      }
    }
    return n;
  };
  EXPECT_EQ(amber_pixels(img), 0);
  EXPECT_GT(amber_pixels(cv::imread(with.string())), 100);
}

void ExpectSameMatches(const std::vector<Match>& a, const std::vector<Match>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(a[i].view_id, b[i].view_id);
    EXPECT_EQ(a[i].roll, b[i].roll);
    EXPECT_EQ(a[i].hand, b[i].hand);
    EXPECT_EQ(a[i].distance, b[i].distance);
    EXPECT_EQ(a[i].score, b[i].score);
    EXPECT_EQ(a[i].landmark_error, b[i].landmark_error);
  }
}

class PictureSearchTest : public SyntheticPictureTest {
 protected:
  // A database of synthetic views whose keypoints are known in their normalised frame.
  std::shared_ptr<const Database> KeypointDatabase() {
    const std::filesystem::path& dir = dir_;
    std::vector<ViewLabel> labels;
    std::vector<std::vector<PointQ>> points;
    for (int i = 0; i < 8; ++i) {
      const SyntheticHand h = Hand(0.4 * i, 0.06 * i);
      const fs::path exr = dir / ("v" + std::to_string(i) + ".exr");
      THROW_CHECK(WriteLabelExr(exr, h.image).ok());
      auto q = LoadQueryEdges(exr, ImageEdgeOptions{});
      THROW_CHECK(q.ok());
      ViewLabel l;
      l.render_id = i;
      l.shape_id = i % 3;
      for (int k = 0; k < kNumKeypoints; ++k) {
        l.keypoints[k] = {static_cast<float>((h.keypoints_px[k][0] - q->centre_x) * q->scale),
                          static_cast<float>((h.keypoints_px[k][1] - q->centre_y) * q->scale),
                          0.0f};
      }
      labels.push_back(l);
      points.push_back(q->points);
    }
    return std::make_shared<const Database>(
        Database::FromMemory(labels, points, 16, {"a", "b", "c"}));
  }
};

// SearchPicture is LoadQueryEdges + Searcher::Search, and with landmarks the network found the
// pool search + RerankByLandmarks: nothing more, nothing less.
TEST_F(PictureSearchTest, EqualsReadingSearchingAndReranking) {
  const auto db = KeypointDatabase();
  const Searcher searcher(db);
  PictureSearchOptions options;
  options.search.top_k = 5;
  options.search.num_threads = 2;
  options.search.hand = Hand::kEither;

  // No landmark model: the edges' search alone.
  const fs::path synthetic = WritePhoto(Hand(1.2, 0.18).image, "q.png", 3);
  auto plain = SearchPicture(searcher, synthetic, options);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_FALSE(plain->landmarks_used);
  EXPECT_FALSE(plain->evidence.landmarks.has_value());
  auto edges = LoadQueryEdges(synthetic, options.picture.edges);
  ASSERT_TRUE(edges.ok());
  EXPECT_TRUE(SamePoints(plain->evidence.edges.points, edges->points));
  auto searched = searcher.Search(edges->points_px(), options.search);
  ASSERT_TRUE(searched.ok());
  ExpectSameMatches(plain->matches, *searched);

  // A real photo with the installed model: its landmarks re-rank the pool search.
  auto landmarker = HandLandmarker::Open(HandLandmarker::DefaultModelPath());
  ASSERT_TRUE(landmarker.ok()) << landmarker.status().ToString();
  options.picture.landmarker = *landmarker;
  const char* source = std::getenv("HANDDB_SOURCE_DIR");
  const fs::path photo = fs::path(source != nullptr ? source : ".") / "tests" / "data" / "photos" /
                         "asl-digits" / "asl-5" / "IMG_1174.JPG";
  auto ranked = SearchPicture(searcher, photo, options);
  ASSERT_TRUE(ranked.ok()) << ranked.status().ToString();
  ASSERT_TRUE(ranked->evidence.landmarks.has_value());
  EXPECT_TRUE(ranked->landmarks_used);
  auto evidence = ReadPicture(photo, options.picture);
  ASSERT_TRUE(evidence.ok());
  edges = LoadQueryEdges(photo, options.picture.edges);
  ASSERT_TRUE(edges.ok());
  EXPECT_TRUE(SamePoints(evidence->edges.points, edges->points));
  SearchOptions pool = options.search;
  pool.top_k = std::max(options.search.top_k, options.landmark_rank.pool_views);
  // Either hand asked; the network names this photo's hand a right one, so only it is searched.
  pool.hand = SearchedHand(*evidence, options.search.hand, options.landmark_rank);
  EXPECT_EQ(pool.hand, Hand::kRight);
  auto pool_matches = searcher.Search(edges->points_px(), pool);
  ASSERT_TRUE(pool_matches.ok());
  const auto expected = RerankByLandmarks(
      std::move(pool_matches).value(), *evidence, options.search, options.landmark_rank);
  ExpectSameMatches(ranked->matches, expected);
  for (const Match& m : ranked->matches) EXPECT_GE(m.score, 0.0);

  // The re-ranking switched off: the search's own order again.
  options.landmark_rank.enabled = false;
  auto unranked = SearchPicture(searcher, photo, options);
  ASSERT_TRUE(unranked.ok());
  EXPECT_FALSE(unranked->landmarks_used);
  searched = searcher.Search(edges->points_px(), options.search);
  ASSERT_TRUE(searched.ok());
  ExpectSameMatches(unranked->matches, *searched);
}

TEST_F(PictureSearchTest, ChecksItsOptions) {
  EXPECT_TRUE(PictureSearchOptions{}.Check());
  PictureSearchOptions bad;
  bad.landmark_rank.weight = -1;
  EXPECT_FALSE(bad.Check());
  bad = PictureSearchOptions{};
  bad.search.top_k = 0;
  EXPECT_FALSE(bad.Check());
  bad = PictureSearchOptions{};
  bad.picture.edges.canny_low = 200;
  EXPECT_FALSE(bad.Check());
  const auto db = KeypointDatabase();
  const Searcher searcher(db);
  auto r = SearchPicture(searcher, WritePhoto(Hand(0.3).image, "q.png"), bad);
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace handdb
