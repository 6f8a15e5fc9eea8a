#include "edges/normalise.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>

#include "edges/synthetic_hand.h"

namespace handdb {
namespace {

int64_t BruteForceDiameter2(const std::vector<EdgePixel>& p) {
  int64_t best = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    for (size_t j = i + 1; j < p.size(); ++j) {
      const int64_t dx = p[i].col - p[j].col;
      const int64_t dy = p[i].row - p[j].row;
      best = std::max(best, dx * dx + dy * dy);
    }
  }
  return best;
}

TEST(Normalise, CalipersMatchBruteForce) {
  std::mt19937 rng(12345);
  for (int trial = 0; trial < 2000; ++trial) {
    const int n = 2 + static_cast<int>(rng() % 60);
    const int range = 1 + static_cast<int>(rng() % 40);
    std::uniform_int_distribution<int> coord(0, range);
    std::vector<EdgePixel> pts;
    const int kind = trial % 3;
    for (int i = 0; i < n; ++i) {
      const int a = coord(rng);
      if (kind == 0) pts.push_back({a, coord(rng)});
      if (kind == 1) pts.push_back({a, 2 * a + 3});  // collinear
      if (kind == 2) pts.push_back({a, (a * a) % (range + 1)});
    }
    auto norm = ComputeNormalisation(pts);
    const int64_t expected = BruteForceDiameter2(pts);
    if (expected == 0) {
      EXPECT_FALSE(norm.ok());
      continue;
    }
    ASSERT_TRUE(norm.ok()) << norm.status().ToString();
    EXPECT_NEAR(norm->diameter, std::sqrt(static_cast<double>(expected)), 1e-9)
        << "trial " << trial;
    const int64_t dx = norm->end_a.col - norm->end_b.col;
    const int64_t dy = norm->end_a.row - norm->end_b.row;
    EXPECT_EQ(dx * dx + dy * dy, expected);
  }
}

TEST(Normalise, HullOfSquareHasFourCorners) {
  std::vector<EdgePixel> pts;
  for (int r = 0; r < 5; ++r)
    for (int c = 0; c < 5; ++c) pts.push_back({c, r});
  const auto hull = ConvexHull(pts);
  EXPECT_EQ(hull.size(), 4u);
}

TEST(Normalise, EmptyAndSinglePointAreNoHand) {
  std::vector<EdgePixel> none;
  EXPECT_EQ(ComputeNormalisation(none).status().code(), StatusCode::kNoHand);
  std::vector<EdgePixel> one = {{3, 4}, {3, 4}};
  EXPECT_EQ(ComputeNormalisation(one).status().code(), StatusCode::kNoHand);
}

TEST(Normalise, DiameterIs192) {
  for (double scale : {0.6, 1.0, 1.3}) {
    SyntheticHandParams params;
    params.scale = scale;
    params.angle = 0.4;
    const SyntheticHand hand = RenderSyntheticHand(params);
    const EdgeResult edges = ExtractEdges(hand.image, DefaultJointPairs(), EdgeOptions{});
    auto norm = ComputeNormalisation(edges.silhouette);
    ASSERT_TRUE(norm.ok());
    EXPECT_NEAR(norm->scale * norm->diameter, 192.0, 1e-9);
    const std::vector<PointQ> pts = NormalisePixels(edges.edges, *norm);
    double best = 0;
    double max_x = -1e9, min_x = 1e9;
    for (size_t i = 0; i < pts.size(); ++i) {
      for (size_t j = i + 1; j < pts.size(); ++j) {
        const double dx = PointQToPx(pts[i].x) - PointQToPx(pts[j].x);
        const double dy = PointQToPx(pts[i].y) - PointQToPx(pts[j].y);
        best = std::max(best, std::hypot(dx, dy));
      }
      max_x = std::max<double>(max_x, PointQToPx(pts[i].x));
      min_x = std::min<double>(min_x, PointQToPx(pts[i].x));
    }
    EXPECT_NEAR(best, 192.0, 1.0) << "scale " << scale;
    // The origin (hull centroid) lies inside the point set's extent.
    EXPECT_GT(max_x, 0.0);
    EXPECT_LT(min_x, 0.0);
    EXPECT_LE(max_x - min_x, 192.0 + 0.1);
    // Output sorted by (y, x) without duplicates.
    for (size_t i = 1; i < pts.size(); ++i) {
      EXPECT_TRUE(pts[i - 1].y < pts[i].y || (pts[i - 1].y == pts[i].y && pts[i - 1].x < pts[i].x));
    }
  }
}

TEST(Normalise, CentreIsTheHullCentroid) {
  // A filled 11 x 5 rectangle's boundary: the hull is the rectangle, its centroid the middle.
  std::vector<EdgePixel> pts;
  for (int c = 10; c <= 20; ++c) pts.insert(pts.end(), {{c, 30}, {c, 34}});
  for (int r = 31; r <= 33; ++r) pts.insert(pts.end(), {{10, r}, {20, r}});
  auto norm = ComputeNormalisation(pts);
  ASSERT_TRUE(norm.ok());
  EXPECT_NEAR(norm->centre_x, 15.5, 1e-9);
  EXPECT_NEAR(norm->centre_y, 32.5, 1e-9);
  EXPECT_NEAR(norm->diameter, std::hypot(10.0, 4.0), 1e-9);
  // A triangle: the area centroid, not the vertex mean of the (dense) boundary.
  std::vector<EdgePixel> tri = {{0, 0}, {30, 0}, {0, 30}, {1, 0}, {2, 0}, {3, 0}, {4, 0}};
  norm = ComputeNormalisation(tri);
  ASSERT_TRUE(norm.ok());
  EXPECT_NEAR(norm->centre_x, 10.5, 1e-9);
  EXPECT_NEAR(norm->centre_y, 10.5, 1e-9);
  // Collinear points: the midpoint of the segment.
  std::vector<EdgePixel> line = {{2, 2}, {4, 3}, {6, 4}};
  norm = ComputeNormalisation(line);
  ASSERT_TRUE(norm.ok());
  EXPECT_NEAR(norm->centre_x, 4.5, 1e-9);
  EXPECT_NEAR(norm->centre_y, 3.5, 1e-9);
}

// The centre must follow the hand, not the pixel grid: rendered at many angles and sub-pixel
// offsets, the centre mapped back into the hand's frame stays put (the diameter's midpoint moved
// by up to 15 normalised px here, when two near-equal diameters swapped).
TEST(Normalise, CentreIsStableUnderRotation) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  for (int shape = 0; shape < 3; ++shape) {
    SyntheticHandParams base;
    for (int f = 0; f < 5; ++f) {
      base.bend[f] = (u(rng) - 0.5) * 0.6;
      base.folded[f] = u(rng) < 0.25;
    }
    std::vector<std::array<double, 2>> centres;
    for (int i = 0; i < 24; ++i) {
      SyntheticHandParams p = base;
      p.angle = u(rng) * 2 * M_PI;
      p.centre_x = 128 + u(rng) - 0.5;
      p.centre_y = 128 + u(rng) - 0.5;
      const SyntheticHand hand = RenderSyntheticHand(p);
      auto norm = ComputeNormalisation(
          ExtractEdges(hand.image, DefaultJointPairs(), EdgeOptions{}).silhouette);
      ASSERT_TRUE(norm.ok());
      const double dx = norm->centre_x - p.centre_x;
      const double dy = norm->centre_y - p.centre_y;
      const double c = std::cos(p.angle), s = std::sin(p.angle);
      centres.push_back({(c * dx + s * dy) * norm->scale, (-s * dx + c * dy) * norm->scale});
    }
    double mx = 0, my = 0;
    for (const auto& c : centres) {
      mx += c[0] / centres.size();
      my += c[1] / centres.size();
    }
    for (const auto& c : centres) {
      EXPECT_LT(std::hypot(c[0] - mx, c[1] - my), 0.6) << "shape " << shape;
    }
  }
}

TEST(Normalise, KeypointsFollowTheSameMap) {
  Normalisation norm;
  norm.centre_x = 100;
  norm.centre_y = 50;
  norm.diameter = 96;
  norm.scale = 2;
  const auto kp = NormaliseKeypoint({110.0, 40.0, -3.0}, norm);
  EXPECT_FLOAT_EQ(kp[0], 20.0f);
  EXPECT_FLOAT_EQ(kp[1], -20.0f);
  EXPECT_FLOAT_EQ(kp[2], -6.0f);
}

}  // namespace
}  // namespace handdb
