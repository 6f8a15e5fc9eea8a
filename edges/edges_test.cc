#include "edges/edges.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>
#include <utility>

namespace handdb {
namespace {

LabelImage Blank(int w, int h) {
  LabelImage img;
  img.width = w;
  img.height = h;
  img.labels.assign(static_cast<size_t>(w) * h, 0);
  img.depth.assign(static_cast<size_t>(w) * h, 1e10f);
  return img;
}

// Fills columns [c0, c1] x rows [r0, r1] (inclusive).
void Fill(LabelImage* img, int c0, int c1, int r0, int r1, uint8_t label, float depth) {
  for (int r = r0; r <= r1; ++r) {
    for (int c = c0; c <= c1; ++c) {
      img->labels[static_cast<size_t>(r) * img->width + c] = label;
      img->depth[static_cast<size_t>(r) * img->width + c] = depth;
    }
  }
}

std::set<std::pair<int, int>> AsSet(const std::vector<EdgePixel>& v) {
  std::set<std::pair<int, int>> s;
  for (const auto& p : v) s.insert({p.col, p.row});
  return s;
}

// The outline of the rectangle cols 2..17, rows 2..7.
std::set<std::pair<int, int>> RectOutline() {
  std::set<std::pair<int, int>> s;
  for (int c = 2; c <= 17; ++c) {
    s.insert({c, 2});
    s.insert({c, 7});
  }
  for (int r = 3; r <= 6; ++r) {
    s.insert({2, r});
    s.insert({17, r});
  }
  return s;
}

// Two links side by side: cols 2..9 and 10..17, rows 2..7.
LabelImage TwoLinks(uint8_t left, uint8_t right, float left_depth, float right_depth) {
  LabelImage img = Blank(20, 10);
  Fill(&img, 2, 9, 2, 7, left, left_depth);
  Fill(&img, 10, 17, 2, 7, right, right_depth);
  return img;
}

TEST(Edges, DefaultJointPairsAreTheFifteenJoints) {
  const JointPairs pairs = DefaultJointPairs();
  EXPECT_EQ(pairs.size(), 15);
  EXPECT_TRUE(pairs.Contains(1, 2));
  EXPECT_TRUE(pairs.Contains(3, 2));
  EXPECT_TRUE(pairs.Contains(1, 14));
  EXPECT_TRUE(pairs.Contains(15, 16));
  EXPECT_FALSE(pairs.Contains(1, 3));  // palm - thumb link 2
  EXPECT_FALSE(pairs.Contains(4, 5));  // thumb tip - index link 1
  EXPECT_FALSE(pairs.Contains(7, 8));  // index tip - middle link 1
  EXPECT_FALSE(pairs.Contains(0, 1));
}

TEST(Edges, JointBorderDropped) {
  const LabelImage img = TwoLinks(1, 5, 1.0f, 1.0f);  // palm - index link 1
  const EdgeResult r = ExtractEdges(img, DefaultJointPairs(), EdgeOptions{});
  EXPECT_EQ(AsSet(r.edges), RectOutline());
  EXPECT_EQ(AsSet(r.silhouette), RectOutline());
  EXPECT_EQ(r.num_hand_pixels, 16 * 6);
  EXPECT_FALSE(r.touches_border);
}

TEST(Edges, NonJointBorderKept) {
  const LabelImage img = TwoLinks(1, 9, 1.0f, 1.0f);  // palm - middle link 2
  const EdgeResult r = ExtractEdges(img, DefaultJointPairs(), EdgeOptions{});
  auto expected = RectOutline();
  // Equal depth: the first pixel in raster order (the left one) carries the edge.
  for (int row = 3; row <= 6; ++row) expected.insert({9, row});
  EXPECT_EQ(AsSet(r.edges), expected);
  EXPECT_EQ(AsSet(r.silhouette), RectOutline());
}

TEST(Edges, NearerSideCarriesTheEdge) {
  const LabelImage img = TwoLinks(1, 9, 1.0f, 0.9f);  // right link nearer
  const EdgeResult r = ExtractEdges(img, DefaultJointPairs(), EdgeOptions{});
  auto expected = RectOutline();
  for (int row = 3; row <= 6; ++row) expected.insert({10, row});
  EXPECT_EQ(AsSet(r.edges), expected);
}

TEST(Edges, SilhouetteAlwaysKept) {
  // A single link: only the silhouette, whatever the options.
  LabelImage img = Blank(12, 12);
  Fill(&img, 3, 8, 4, 9, 7, 1.0f);
  for (bool occlusion : {false, true}) {
    EdgeOptions opt;
    opt.occlusion_edges = occlusion;
    const EdgeResult r = ExtractEdges(img, DefaultJointPairs(), opt);
    EXPECT_EQ(r.edges.size(), 6u * 2 + 4u * 2);
    EXPECT_EQ(AsSet(r.edges), AsSet(r.silhouette));
  }
  // Without any joint pairs every link border is kept too, and the silhouette is unchanged.
  const LabelImage two = TwoLinks(1, 5, 1.0f, 1.0f);
  const EdgeResult r = ExtractEdges(two, JointPairs(), EdgeOptions{});
  EXPECT_EQ(r.edges.size(), RectOutline().size() + 4);
  EXPECT_EQ(AsSet(r.silhouette), RectOutline());
}

TEST(Edges, DepthJumpKeepsJointBorderAsOcclusionEdge) {
  // Index link 1 folded over the palm: 2 cm nearer.
  const LabelImage img = TwoLinks(1, 5, 1.0f, 0.98f);
  EdgeOptions on;
  on.occlusion_edges = true;
  on.depth_jump = 0.005f;
  auto expected = RectOutline();
  for (int row = 3; row <= 6; ++row) expected.insert({10, row});
  EXPECT_EQ(AsSet(ExtractEdges(img, DefaultJointPairs(), on).edges), expected);

  EdgeOptions off = on;
  off.occlusion_edges = false;
  EXPECT_EQ(AsSet(ExtractEdges(img, DefaultJointPairs(), off).edges), RectOutline());

  // Below the threshold: a continuous joint, dropped.
  EdgeOptions high = on;
  high.depth_jump = 0.05f;
  EXPECT_EQ(AsSet(ExtractEdges(img, DefaultJointPairs(), high).edges), RectOutline());

  // No depth: joint borders are dropped.
  LabelImage no_depth = img;
  no_depth.depth.clear();
  EXPECT_EQ(AsSet(ExtractEdges(no_depth, DefaultJointPairs(), on).edges), RectOutline());
}

TEST(Edges, TouchingBorderAndEmpty) {
  LabelImage img = Blank(10, 10);
  EdgeResult r = ExtractEdges(img, DefaultJointPairs(), EdgeOptions{});
  EXPECT_EQ(r.num_hand_pixels, 0);
  EXPECT_TRUE(r.edges.empty());
  Fill(&img, 0, 3, 4, 6, 1, 1.0f);
  r = ExtractEdges(img, DefaultJointPairs(), EdgeOptions{});
  EXPECT_TRUE(r.touches_border);
  // The contour stays closed: the pixels on the image border are silhouette pixels.
  EXPECT_EQ(AsSet(r.silhouette).count({0, 5}), 1u);
}

TEST(Edges, OptionsCheck) {
  EdgeOptions ok;
  EXPECT_TRUE(ok.Check());
  EdgeOptions bad;
  bad.depth_jump = 0.0f;
  EXPECT_FALSE(bad.Check());
}

TEST(Edges, RejectsLabelsOutOfRange) {
  LabelImage img = Blank(4, 4);
  img.labels[5] = 17;
  EXPECT_THROW(ExtractEdges(img, DefaultJointPairs(), EdgeOptions{}), std::logic_error);
}

}  // namespace
}  // namespace handdb
