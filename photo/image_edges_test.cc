#include "photo/image_edges.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <random>
#include <string>

#include "edges/edges.h"
#include "edges/exr_io.h"
#include "edges/normalise.h"
#include "edges/synthetic_hand.h"
#include "photo/photo_testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

using ImageEdgesTest = SyntheticPictureTest;

double Diameter(const std::vector<PointQ>& pts) {
  double best = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    for (size_t j = i + 1; j < pts.size(); ++j) {
      best = std::max(best, std::hypot(double(pts[i].x - pts[j].x), double(pts[i].y - pts[j].y)));
    }
  }
  return best / kPointScale;
}

TEST_F(ImageEdgesTest, LabelEdgeAndPhotoInputsShareTheDatabaseNormalisation) {
  const SyntheticHand hand = Hand(0.3);
  const fs::path exr = dir_ / "hand.exr";
  ASSERT_TRUE(WriteLabelExr(exr, hand.image).ok());
  auto labels = LoadQueryEdges(exr, ImageEdgeOptions{});
  ASSERT_TRUE(labels.ok()) << labels.status().ToString();
  EXPECT_EQ(labels->kind, QueryInputKind::kLabels);
  EXPECT_NEAR(Diameter(labels->points), 192.0, 0.2);

  auto edges = LoadQueryEdges(WriteEdgeImage(hand.image, "edges.png"), ImageEdgeOptions{});
  ASSERT_TRUE(edges.ok()) << edges.status().ToString();
  EXPECT_EQ(edges->kind, QueryInputKind::kEdges);
  // Same pixels, same normalisation: identical points.
  EXPECT_EQ(edges->diameter_px, labels->diameter_px);
  EXPECT_EQ(edges->centre_x, labels->centre_x);
  EXPECT_EQ(edges->centre_y, labels->centre_y);
  ASSERT_EQ(edges->points.size(), labels->points.size());

  auto photo = LoadQueryEdges(WritePhoto(hand.image, "photo.png"), ImageEdgeOptions{});
  ASSERT_TRUE(photo.ok()) << photo.status().ToString();
  EXPECT_EQ(photo->kind, QueryInputKind::kPhoto);
  // Skin segmentation recovers the silhouette: same normalisation (within a pixel).
  EXPECT_NEAR(photo->diameter_px, labels->diameter_px, 1.5);
  EXPECT_NEAR(photo->centre_x, labels->centre_x, 1.0);
  EXPECT_NEAR(photo->centre_y, labels->centre_y, 1.0);
  EXPECT_GT(photo->points.size(), labels->points.size() / 2);
}

TEST_F(ImageEdgesTest, LabelQueryUsesTheGivenEdgeOptions) {
  SyntheticHandParams p;
  p.folded = {false, true, true, false, false};  // two fingers folded over the palm
  const SyntheticHand hand = RenderSyntheticHand(p);
  const fs::path exr = dir_ / "folded.exr";
  ASSERT_TRUE(WriteLabelExr(exr, hand.image).ok());
  auto points = [&](const EdgeOptions& edges) {
    ImageEdgeOptions o;
    o.label_edges = edges;
    auto q = LoadQueryEdges(exr, o);
    EXPECT_TRUE(q.ok()) << q.status().ToString();
    return q.ok() ? q->points : std::vector<PointQ>{};
  };
  EdgeOptions off;
  off.occlusion_edges = false;
  // The converter's own rule gives the same points as the query path, for each option.
  for (const EdgeOptions& e : {EdgeOptions{}, off}) {
    const EdgeResult direct = ExtractEdges(hand.image, DefaultJointPairs(), e);
    auto norm = ComputeNormalisation(direct.silhouette);
    ASSERT_TRUE(norm.ok());
    auto xy = [](const std::vector<PointQ>& v) {
      std::vector<std::pair<int, int>> out;
      for (const PointQ& q : v) out.emplace_back(q.x, q.y);
      return out;
    };
    EXPECT_EQ(xy(points(e)), xy(NormalisePixels(direct.edges, *norm)));
  }
  EXPECT_GT(points(EdgeOptions{}).size(), points(off).size());  // occlusion edges add points
  ImageEdgeOptions bad;
  bad.label_edges.depth_jump = 0;
  EXPECT_FALSE(bad.Check());
}

// keypoints_image_px: a database of label-path synthetic hands whose labels carry
// their exact keypoints in the normalised frame; photos of one of them, as is (a right hand) and
// mirrored (a left hand), must give that hand's true keypoints in the photo's pixels within ~1 px
// after undoing the roll, the mirror and the normalisation.
TEST_F(ImageEdgesTest, MaskAndRoi) {
  const SyntheticHand hand = Hand(-0.4);
  const fs::path photo = WritePhoto(hand.image, "p.png");
  // A mask replaces skin colour: here a mask of the true hand region.
  cv::Mat mask = cv::Mat::zeros(hand.image.height, hand.image.width, CV_8U);
  for (int y = 0; y < mask.rows; ++y) {
    for (int x = 0; x < mask.cols; ++x) mask.at<uint8_t>(y, x) = hand.image.label(x, y) ? 255 : 0;
  }
  ASSERT_TRUE(cv::imwrite((dir_ / "mask.png").string(), mask));
  ImageEdgeOptions o;
  o.mask = dir_ / "mask.png";
  auto with_mask = LoadQueryEdges(photo, o);
  ASSERT_TRUE(with_mask.ok()) << with_mask.status().ToString();
  // Counted at the working size and scaled back: close to the mask's own count.
  EXPECT_NEAR(
      double(with_mask->hand_pixels), cv::countNonZero(mask), 0.03 * cv::countNonZero(mask));

  // A wrong-size mask, a missing mask.
  ASSERT_TRUE(cv::imwrite((dir_ / "small.png").string(), cv::Mat::zeros(10, 10, CV_8U)));
  o.mask = dir_ / "small.png";
  EXPECT_EQ(LoadQueryEdges(photo, o).status().code(), StatusCode::kBadImage);
  o.mask = dir_ / "none.png";
  EXPECT_EQ(LoadQueryEdges(photo, o).status().code(), StatusCode::kNotFound);

  // An ROI away from the hand finds nothing; one outside the image is a bad argument.
  ImageEdgeOptions r;
  r.roi = {0, 0, 20, 20};
  EXPECT_EQ(LoadQueryEdges(photo, r).status().code(), StatusCode::kNoHand);
  r.roi = {300, 280, 50, 50};
  EXPECT_EQ(LoadQueryEdges(photo, r).status().code(), StatusCode::kInvalidArgument);
  r.roi = {0, 0, 320, 300};
  EXPECT_TRUE(LoadQueryEdges(photo, r).ok());
}

TEST_F(ImageEdgesTest, BadInputs) {
  ImageEdgeOptions o;
  EXPECT_EQ(LoadQueryEdges(dir_ / "missing.png", o).status().code(), StatusCode::kNotFound);
  {
    std::ofstream f(dir_ / "garbage.png");
    f << "this is not a png";
  }
  auto garbage = LoadQueryEdges(dir_ / "garbage.png", o);
  EXPECT_EQ(garbage.status().code(), StatusCode::kBadImage);
  EXPECT_NE(garbage.status().message().find("garbage.png"), std::string::npos);
  // No skin anywhere.
  ASSERT_TRUE(cv::imwrite((dir_ / "blue.png").string(),
                          cv::Mat(100, 120, CV_8UC3, cv::Scalar(200, 60, 20))));
  auto blue = LoadQueryEdges(dir_ / "blue.png", o);
  EXPECT_EQ(blue.status().code(), StatusCode::kNoHand);
  // An all-black edge image, forced as edges.
  ASSERT_TRUE(cv::imwrite((dir_ / "black.png").string(), cv::Mat::zeros(50, 50, CV_8U)));
  o.kind = QueryInputKind::kEdges;
  EXPECT_EQ(LoadQueryEdges(dir_ / "black.png", o).status().code(), StatusCode::kNoHand);
  // A label EXR that is not an EXR.
  o.kind = QueryInputKind::kAuto;
  {
    std::ofstream f(dir_ / "bad.exr");
    f << "nope";
  }
  EXPECT_FALSE(LoadQueryEdges(dir_ / "bad.exr", o).ok());
}

// The hand region of `li` (label != 0) as a mask.
cv::Mat HandMask(const LabelImage& li) {
  cv::Mat m = cv::Mat::zeros(li.height, li.width, CV_8U);
  for (int y = 0; y < li.height; ++y) {
    for (int x = 0; x < li.width; ++x) m.at<uint8_t>(y, x) = li.label(x, y) ? 255 : 0;
  }
  return m;
}

// The undirected chamfer distance of two normalised point sets, px.
double Chamfer(const std::vector<PointQ>& a, const std::vector<PointQ>& b) {
  const auto one_way = [](const std::vector<PointQ>& x, const std::vector<PointQ>& y) {
    double sum = 0;
    for (const PointQ& p : x) {
      double best = 1e30;
      for (const PointQ& q : y) {
        best = std::min(best, std::hypot(double(p.x - q.x), double(p.y - q.y)));
      }
      sum += best;
    }
    return sum / x.size() / kPointScale;
  };
  return one_way(a, b) + one_way(b, a);
}

TEST_F(ImageEdgesTest, ThePictureSizeDoesNotChangeTheEdges) {
  // The same photo at 1x and 3x: resampled to the working size first, both give the same
  // normalised edges (kernels and Canny thresholds no longer depend on the picture's size).
  const fs::path small = WritePhoto(Hand(0.3).image, "small.png", 3);
  cv::Mat big;
  cv::resize(cv::imread(small.string()), big, cv::Size(), 3, 3, cv::INTER_CUBIC);
  ASSERT_TRUE(cv::imwrite((dir_ / "big.png").string(), big));
  auto a = LoadQueryEdges(small, ImageEdgeOptions{});
  auto b = LoadQueryEdges(dir_ / "big.png", ImageEdgeOptions{});
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_NEAR(b->diameter_px, 3 * a->diameter_px, 0.03 * 3 * a->diameter_px);
  EXPECT_NEAR(b->work_scale, a->work_scale / 3, 0.03 * a->work_scale);
  EXPECT_LT(Chamfer(a->points, b->points), 2.0);  // px of the 192 px normalised hand
  // The map back to the picture: the normalised centre lands on the hand's centre.
  const Point2f c = b->ImageFromNormalised({0, 0});
  EXPECT_NEAR(c.x, b->centre_x, 1e-3);
  EXPECT_NEAR(c.y, b->centre_y, 1e-3);
  EXPECT_NEAR(b->centre_x, 3 * a->centre_x, 3.0);
  EXPECT_EQ(b->width, 3 * 320);
}

// A frame decoded in memory (a video's) gives the evidence its PNG file gives, bit for bit: a
// photo and an edge image, through every field of the edges.
TEST_F(ImageEdgesTest, PixelsInMemoryGiveTheEvidenceOfTheirFile) {
  const fs::path photo = WritePhoto(Hand(0.4).image, "frame.png", 5);
  const fs::path edges = WriteEdgeImage(Hand(-0.2).image, "edges.png");
  for (const fs::path& file : {photo, edges}) {
    const cv::Mat decoded = cv::imread(file.string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(decoded.empty());
    PicturePixels pixels;
    pixels.width = decoded.cols;
    pixels.height = decoded.rows;
    pixels.channels = decoded.channels();
    pixels.data = decoded.data;
    pixels.row_bytes = decoded.step[0];
    auto a = ReadPicture(file, PictureOptions{});
    auto b = ReadPicturePixels(file.string(), pixels, PictureOptions{});
    ASSERT_TRUE(a.ok()) << a.status().ToString();
    ASSERT_TRUE(b.ok()) << b.status().ToString();
    EXPECT_EQ(a->edges.kind, b->edges.kind);
    ASSERT_EQ(a->edges.points.size(), b->edges.points.size());
    for (size_t i = 0; i < a->edges.points.size(); ++i) {
      EXPECT_EQ(a->edges.points[i].x, b->edges.points[i].x);
      EXPECT_EQ(a->edges.points[i].y, b->edges.points[i].y);
    }
    EXPECT_EQ(a->edges.centre_x, b->edges.centre_x);
    EXPECT_EQ(a->edges.centre_y, b->edges.centre_y);
    EXPECT_EQ(a->edges.scale, b->edges.scale);
    EXPECT_EQ(a->edges.hand_pixels, b->edges.hand_pixels);
    EXPECT_EQ(a->edges.edge_pixels.size(), b->edges.edge_pixels.size());
  }
  PicturePixels none;
  auto bad = ReadPicturePixels("frame 7", none, PictureOptions{});
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kBadImage);
  EXPECT_NE(bad.status().message().find("frame 7"), std::string::npos);
}

// The hand's largest inscribed circle's radius, px.
double PalmRadius(const LabelImage& li) {
  cv::Mat dt;
  cv::distanceTransform(HandMask(li), dt, cv::DIST_L2, 5);
  double palm_radius = 0;
  cv::minMaxLoc(dt, nullptr, &palm_radius);
  return palm_radius;
}

// The unit vector from the middle finger's base to the wrist: where `h`'s forearm goes.
cv::Point2d ArmDirection(const SyntheticHand& h) {
  const auto& wrist = h.keypoints_px[0];
  const auto& middle = h.keypoints_px[9];
  const cv::Point2d u(wrist[0] - middle[0], wrist[1] - middle[1]);
  return u / std::hypot(u.x, u.y);
}

// `h` with a skin-coloured forearm (label 1) from the wrist along ArmDirection out of the
// picture; 1.7 palm radii wide, narrower than the palm.
LabelImage WithForearm(const SyntheticHand& h) {
  LabelImage with_arm = h.image;
  const double palm_radius = PalmRadius(h.image);
  const auto& wrist = h.keypoints_px[0];
  const cv::Point2d u = ArmDirection(h);
  cv::Mat arm = cv::Mat::zeros(with_arm.height, with_arm.width, CV_8U);
  cv::line(arm,
           cv::Point(int(wrist[0]), int(wrist[1])),
           cv::Point(int(wrist[0] + 1000 * u.x), int(wrist[1] + 1000 * u.y)),
           255,
           int(1.7 * palm_radius));
  for (int y = 0; y < arm.rows; ++y) {
    for (int x = 0; x < arm.cols; ++x) {
      if (arm.at<uint8_t>(y, x) && with_arm.label(x, y) == 0) {
        with_arm.labels[size_t(y) * with_arm.width + x] = 1;
      }
    }
  }
  return with_arm;
}

TEST_F(ImageEdgesTest, ForearmIsCutOffAtTheWrist) {
  const SyntheticHand h = Hand(0);
  const LabelImage with_arm = WithForearm(h);
  const double palm_radius = PalmRadius(h.image);
  const cv::Point2d u = ArmDirection(h);
  auto hand = LoadQueryEdges(WritePhoto(h.image, "hand.png"), ImageEdgeOptions{});
  auto cut = LoadQueryEdges(WritePhoto(with_arm, "arm.png"), ImageEdgeOptions{});
  ImageEdgeOptions keep_arm;
  keep_arm.cut_forearm = false;
  auto uncut = LoadQueryEdges(WritePhoto(with_arm, "arm.png"), keep_arm);
  ASSERT_TRUE(hand.ok()) << hand.status().ToString();
  ASSERT_TRUE(cut.ok()) << cut.status().ToString();
  ASSERT_TRUE(uncut.ok()) << uncut.status().ToString();
  EXPECT_FALSE(hand->forearm_cut);  // a hand that does not reach the border is left alone
  EXPECT_TRUE(cut->forearm_cut);
  EXPECT_FALSE(uncut->forearm_cut);
  // With the cut, the normalisation is nearly the hand's own; without it the arm sets it.
  EXPECT_NEAR(cut->diameter_px, hand->diameter_px, 0.15 * hand->diameter_px);
  EXPECT_GT(uncut->diameter_px, 1.3 * hand->diameter_px);
  EXPECT_LT(Chamfer(cut->points, hand->points), 0.5 * Chamfer(uncut->points, hand->points));
  // The cut line lies below the palm centre (the arm leaves at the bottom), across the arm.
  EXPECT_GT(cut->wrist_line[1], cut->palm_centre_y);
  EXPECT_GT(cut->wrist_line[3], cut->palm_centre_y);
  EXPECT_GT(cut->palm_radius_px, 0.8 * palm_radius);
  // The arm's direction: a unit vector along the drawn arm (wrist away from the middle finger),
  // none for the hand alone, nor with the wrist cut off (no arm is looked for).
  EXPECT_FALSE(hand->arm_found);
  EXPECT_FALSE(uncut->arm_found);
  ASSERT_TRUE(cut->arm_found);
  EXPECT_NEAR(std::hypot(cut->arm_dir_x, cut->arm_dir_y), 1.0, 1e-9);
  EXPECT_GT(cut->arm_dir_x * u.x + cut->arm_dir_y * u.y, std::cos(0.35));  // within 20 deg
}

// A forearm leaving the picture with a dark band across it (a bracelet worn at a slant) that
// crosses the bottom border: the region's own run along the border is only the stretch on the
// hand's side of the band, narrower than an arm, yet the arm lies just inside the band. It is an
// arm: cut off at the wrist and the picture accepted. Fingers cut by the border are still refused.
TEST_F(ImageEdgesTest, AForearmWithABandAcrossItIsStillAnArm) {
  const SyntheticHand h = Hand(0);
  const LabelImage with_arm = WithForearm(h);
  const double palm_radius = PalmRadius(h.image);
  const cv::Point2d u = ArmDirection(h);
  ASSERT_GT(u.y, 0.9);  // the arm leaves by the bottom
  const auto& wrist = h.keypoints_px[0];
  const double bottom = with_arm.height - 1;
  const double arm_x = wrist[0] + (bottom - wrist[1]) * u.x / u.y;  // where the arm leaves
  const double arm_width = 1.7 * palm_radius;
  // The band meets the border a third of the arm's width from its right side and rises, at 15
  // degrees, to the left across the arm.
  const cv::Point2d meet(arm_x + 0.5 * arm_width - arm_width / 3, bottom + 2);
  const cv::Point2d dir(-std::cos(0.26), -std::sin(0.26));
  const fs::path path = WritePhoto(with_arm, "band.png");
  cv::Mat img = cv::imread(path.string());
  cv::line(img,
           cv::Point(meet),
           cv::Point(meet + 3 * arm_width * dir),
           cv::Scalar(25, 25, 25),
           std::max(3, static_cast<int>(0.3 * palm_radius)));
  ASSERT_TRUE(cv::imwrite(path.string(), img));
  auto hand = LoadQueryEdges(WritePhoto(h.image, "hand.png"), ImageEdgeOptions{});
  auto band = LoadQueryEdges(path, ImageEdgeOptions{});
  ASSERT_TRUE(hand.ok()) << hand.status().ToString();
  ASSERT_TRUE(band.ok()) << band.status().ToString();
  EXPECT_TRUE(band->arm_found);
  EXPECT_TRUE(band->forearm_cut);
  EXPECT_GT(band->arm_dir_x * u.x + band->arm_dir_y * u.y, std::cos(0.35));  // within 20 deg
  EXPECT_NEAR(band->diameter_px, hand->diameter_px, 0.15 * hand->diameter_px);

  // Spread fingers that leave the picture at the top are no arm, band or not.
  SyntheticHandParams p;
  p.width = 320;
  p.height = 200;
  p.centre_x = 160;
  p.centre_y = 85;
  p.bend = {0.3, -0.25, 0, 0.25, 0.45};
  auto cut =
      LoadQueryEdges(WritePhoto(RenderSyntheticHand(p).image, "cut.png"), ImageEdgeOptions{});
  EXPECT_EQ(cut.status().code(), StatusCode::kNoHand);
  EXPECT_NE(cut.status().message().find("cut.png: the hand is cut by the picture's border"),
            std::string::npos)
      << cut.status().message();
}

TEST_F(ImageEdgesTest, PicturesTheSearchCannotUseAreRefusedInOneLine) {
  const SyntheticHand h = Hand(0);
  ImageEdgeOptions o;
  // Two hands side by side.
  LabelImage two;
  two.width = 2 * h.image.width;
  two.height = h.image.height;
  two.labels.assign(size_t(two.width) * two.height, 0);
  for (int y = 0; y < h.image.height; ++y) {
    for (int x = 0; x < h.image.width; ++x) {
      const uint16_t l = h.image.label(x, y);
      two.labels[size_t(y) * two.width + x] = l;
      two.labels[size_t(y) * two.width + x + h.image.width] = l;
    }
  }
  const fs::path two_path = WritePhoto(two, "two.png");
  auto r = LoadQueryEdges(two_path, o);
  EXPECT_EQ(r.status().code(), StatusCode::kNoHand);
  EXPECT_NE(r.status().message().find("two.png: two hand-sized skin-coloured regions"),
            std::string::npos)
      << r.status().message();
  o.roi = {0, 0, h.image.width, h.image.height};  // one of them
  EXPECT_TRUE(LoadQueryEdges(two_path, o).ok());
  o = {};

  // A hand whose fingers leave the picture at the top.
  SyntheticHandParams p;
  p.width = 320;
  p.height = 200;
  p.centre_x = 160;
  p.centre_y = 85;
  p.bend = {0.3, -0.25, 0, 0.25, 0.45};  // spread: separate fingers cross the top
  const fs::path cut_path = WritePhoto(RenderSyntheticHand(p).image, "cut.png");
  r = LoadQueryEdges(cut_path, o);
  EXPECT_EQ(r.status().code(), StatusCode::kNoHand);
  EXPECT_NE(r.status().message().find("cut.png: the hand is cut by the picture's border"),
            std::string::npos)
      << r.status().message();

  // A hand with its arm, cropped through both by the right side: the hand's stretch of that side
  // runs round the corner into the arm's along the bottom, which may not hide it.
  const LabelImage with_arm = WithForearm(h);
  const auto& wrist = h.keypoints_px[0];
  ASSERT_TRUE(LoadQueryEdges(WritePhoto(with_arm, "arm.png"), o).ok());
  LabelImage cropped;
  cropped.width = static_cast<int>(wrist[0]) + 6;
  cropped.height = with_arm.height;
  for (int y = 0; y < cropped.height; ++y) {
    for (int x = 0; x < cropped.width; ++x) cropped.labels.push_back(with_arm.label(x, y));
  }
  r = LoadQueryEdges(WritePhoto(cropped, "side.png"), o);
  EXPECT_EQ(r.status().code(), StatusCode::kNoHand);
  EXPECT_NE(r.status().message().find("side.png: the hand is cut by the picture's border"),
            std::string::npos)
      << r.status().message();

  // A grey picture: no colour to find skin by; a mask makes it usable.
  cv::Mat grey;
  cv::cvtColor(cv::imread(WritePhoto(h.image, "c.png").string()), grey, cv::COLOR_BGR2GRAY);
  ASSERT_TRUE(cv::imwrite((dir_ / "grey.png").string(), grey));
  r = LoadQueryEdges(dir_ / "grey.png", o);
  EXPECT_EQ(r.status().code(), StatusCode::kNoHand);
  EXPECT_NE(r.status().message().find("grey.png: a grey image (320x300)"), std::string::npos)
      << r.status().message();
  EXPECT_NE(r.status().message().find("--mask"), std::string::npos);
  ASSERT_TRUE(cv::imwrite((dir_ / "mask.png").string(), HandMask(h.image)));
  o.mask = dir_ / "mask.png";
  EXPECT_TRUE(LoadQueryEdges(dir_ / "grey.png", o).ok());
}

// Degenerate shapes: a skin-coloured strip a pixel high or wide, or a few px, is refused in one
// line naming the file, not an OpenCV assertion; a hand-sized region too thin to crop too.
TEST_F(ImageEdgesTest, ThinPicturesAreRefusedNamingTheFile) {
  const cv::Vec3b skin(120, 150, 210);  // BGR, inside the default skin box
  for (const cv::Size size : {cv::Size(2000, 1),
                              cv::Size(1, 2000),
                              cv::Size(3000, 4),
                              cv::Size(900, 15),
                              cv::Size(2000, 30),
                              cv::Size(60000, 16)}) {
    const std::string name =
        "strip-" + std::to_string(size.width) + "x" + std::to_string(size.height) + ".png";
    const fs::path path = dir_ / name;
    ASSERT_TRUE(cv::imwrite(path.string(), cv::Mat(size, CV_8UC3, cv::Scalar(skin))));
    std::optional<Result<QueryEdges>> r;
    ASSERT_NO_THROW(r.emplace(LoadQueryEdges(path, ImageEdgeOptions{}))) << name;
    ASSERT_FALSE(r->ok()) << name;
    EXPECT_EQ(r->status().message().rfind(path.string() + ": ", 0), 0u) << r->status().message();
  }
  auto strip = LoadQueryEdges(dir_ / "strip-2000x1.png", ImageEdgeOptions{});
  EXPECT_EQ(strip.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(strip.status().message(),
            (dir_ / "strip-2000x1.png").string() +
                ": a 2000x1 picture is too thin to hold a hand (16 px each way at least)");
}

// A query's points size the search (each kept once per roll and hand): past kMaxQueryPoints the
// picture is refused naming it, whatever its kind; an edge image's pixels are counted before any
// list of them is made.
TEST_F(ImageEdgesTest, EdgePointsPastTheLimitAreRefused) {
  ImageEdgeOptions edges;
  edges.kind = QueryInputKind::kEdges;
  const fs::path filled = dir_ / "filled-600.png";
  ASSERT_TRUE(cv::imwrite(filled.string(), cv::Mat(600, 600, CV_8U, cv::Scalar(255))));
  auto r = LoadQueryEdges(filled, edges);
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(r.status().message(),
            filled.string() +
                ": 360000 edge points, more than the 65536 a query may have (a "
                "hand's outline and creases have a few thousand)");
  const fs::path huge = dir_ / "filled-1100.png";
  ASSERT_TRUE(cv::imwrite(huge.string(), cv::Mat(1100, 1100, CV_8U, cv::Scalar(255))));
  r = LoadQueryEdges(huge, edges);
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(r.status().message(),
            huge.string() +
                ": 1210000 edge pixels, more than the 1048576 an edge image may have "
                "(edges are lines, not filled areas)");
  // A 250 x 250 filled square stays a query (62,500 points), as before.
  const fs::path fits = dir_ / "filled-250.png";
  ASSERT_TRUE(cv::imwrite(fits.string(), cv::Mat(250, 250, CV_8U, cv::Scalar(255))));
  r = LoadQueryEdges(fits, edges);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->points.size(), 62500u);
}

TEST_F(ImageEdgesTest, AHugeJpegIsDecodedReducedNotRefused) {
  // A real 9000 x 8000 JPEG (72 Mpx, above kMaxImagePixels): decoded at half size, the answer in
  // the file's own pixels.
  const SyntheticHand h = Hand(0.2);
  const fs::path src = WritePhoto(h.image, "src.png");
  cv::Mat photo = cv::imread(src.string());
  cv::Mat big(8000, 9000, CV_8UC3, cv::Scalar(140, 110, 90));
  cv::Mat scaled;
  cv::resize(photo, scaled, cv::Size(), 20, 20, cv::INTER_LINEAR);
  scaled(cv::Rect(0, 0, 6400, 6000)).copyTo(big(cv::Rect(1000, 1000, 6400, 6000)));
  const fs::path jpeg = dir_ / "huge.jpg";
  ASSERT_TRUE(cv::imwrite(jpeg.string(), big, {cv::IMWRITE_JPEG_QUALITY, 80}));
  big.release();
  scaled.release();
  auto small = LoadQueryEdges(src, ImageEdgeOptions{});
  auto huge = LoadQueryEdges(jpeg, ImageEdgeOptions{});
  ASSERT_TRUE(small.ok()) << small.status().ToString();
  ASSERT_TRUE(huge.ok()) << huge.status().ToString();
  EXPECT_EQ(huge->width, 9000);
  EXPECT_EQ(huge->height, 8000);
  EXPECT_NEAR(huge->diameter_px, 20 * small->diameter_px, 0.05 * 20 * small->diameter_px);
  EXPECT_NEAR(huge->centre_x, 1000 + 20 * small->centre_x, 40);
  EXPECT_NEAR(huge->centre_y, 1000 + 20 * small->centre_y, 40);
  EXPECT_LT(Chamfer(huge->points, small->points), 3.0);
  for (const EdgePixelXY& p : huge->edge_pixels) {
    ASSERT_LT(p.x, 9000);
    ASSERT_LT(p.y, 8000);
  }
}

TEST(ImageEdges, ParsePixelRectAndOptions) {
  auto r = ParsePixelRect("10,20,30,40");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->x, 10);
  EXPECT_EQ(r->height, 40);
  for (const char* bad : {"", "1,2,3", "1,2,3,4,5", "a,b,c,d", "1,2,0,4", "-1,2,3,4", "1,2,3,4 "}) {
    EXPECT_FALSE(ParsePixelRect(bad).ok()) << bad;
  }
  EXPECT_TRUE(ImageEdgeOptions{}.Check());
  ImageEdgeOptions o;
  o.skin.cr_min = 200;
  o.skin.cr_max = 100;
  EXPECT_FALSE(o.Check());
  o = {};
  o.canny_low = 200;
  o.canny_high = 100;
  EXPECT_FALSE(o.Check());
  EXPECT_EQ(*ParseQueryInputKind("photo"), QueryInputKind::kPhoto);
  EXPECT_FALSE(ParseQueryInputKind("video").ok());
}

}  // namespace
}  // namespace handdb
