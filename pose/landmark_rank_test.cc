#include "pose/landmark_rank.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

#include "query/search_testing.h"

namespace handdb {
namespace {

// A pool of four matches, best D_c first, of shapes 0, 0, 1, 2, each with its own keypoints.
std::vector<Match> Pool() {
  std::vector<Match> pool;
  const double distances[] = {10.0, 10.5, 11.0, 12.0};
  const uint32_t shapes[] = {0, 0, 1, 2};
  for (uint32_t i = 0; i < 4; ++i) {
    Match m;
    m.view_id = i;
    m.distance = distances[i];
    m.label = testing::SyntheticViewLabel(i, 1);
    m.label.shape_id = shapes[i];
    pool.push_back(m);
  }
  return pool;
}

// A photo query whose landmarks lie exactly on `match`'s keypoints (in the picture's px).
PictureEvidence QueryOn(const Match& match, float presence) {
  PictureEvidence picture;
  QueryEdges& q = picture.edges;
  q.kind = QueryInputKind::kPhoto;
  q.centre_x = 60;
  q.centre_y = 70;
  q.scale = 1.6;
  HandLandmarks l;
  for (int k = 0; k < kNumLandmarks; ++k) {
    l.image_px[k] =
        q.ImageFromNormalised({match.label.keypoints[k][0], match.label.keypoints[k][1]});
  }
  l.presence = presence;
  picture.landmarks = l;
  return picture;
}

TEST(LandmarkRankTest, TheViewTheLandmarksFitRisesByTheDocumentedScore) {
  const std::vector<Match> pool = Pool();
  const PictureEvidence q = QueryOn(pool[2], 0.99f);
  EXPECT_NEAR(LandmarkError(q, pool[2]), 0.0, 1e-5);
  // Random keypoints +-90 px apart: far from each other in hand radii.
  EXPECT_GT(LandmarkError(q, pool[0]), 0.3);
  SearchOptions search;
  search.top_k = 4;
  LandmarkRankOptions options;
  const auto ranked = RerankByLandmarks(pool, q, search, options);
  ASSERT_EQ(ranked.size(), 4u);
  EXPECT_EQ(ranked[0].view_id, 2u);
  EXPECT_NEAR(ranked[0].score, 11.0 / 10.0, 1e-5);
  for (size_t i = 0; i < ranked.size(); ++i) {
    const Match& m = ranked[i];
    EXPECT_NEAR(m.landmark_error, LandmarkError(q, m), 1e-12);
    EXPECT_NEAR(m.score, m.distance / 10.0 + options.weight * m.landmark_error, 1e-12);
    if (i > 0) {
      EXPECT_LE(ranked[i - 1].score, m.score);
    }
  }
  // Weight 0: the D_c order, scores set.
  options.weight = 0;
  const auto by_distance = RerankByLandmarks(pool, q, search, options);
  for (size_t i = 0; i < by_distance.size(); ++i) EXPECT_EQ(by_distance[i].view_id, i);
}

TEST(LandmarkRankTest, KeepsTopKAndThePerShapeLimit) {
  const std::vector<Match> pool = Pool();
  // Landmarks on view 1 (shape 0): with one match per shape, view 1 stands for shape 0 and view
  // 0 (the same shape, nearer by D_c) is dropped.
  const PictureEvidence q = QueryOn(pool[1], 1.0f);
  SearchOptions search;
  search.top_k = 2;
  search.max_per_shape = 1;
  const auto ranked = RerankByLandmarks(pool, q, search, LandmarkRankOptions{});
  ASSERT_EQ(ranked.size(), 2u);
  EXPECT_EQ(ranked[0].view_id, 1u);
  EXPECT_NE(ranked[1].label.shape_id, 0u);
}

TEST(LandmarkRankTest, UnsureOrMissingLandmarksAreNotUsed) {
  const std::vector<Match> pool = Pool();
  LandmarkRankOptions options;
  EXPECT_TRUE(UsesLandmarks(QueryOn(pool[0], 0.95f), options));
  EXPECT_FALSE(UsesLandmarks(QueryOn(pool[0], 0.5f), options));
  EXPECT_FALSE(UsesLandmarks(PictureEvidence{}, options));
  options.enabled = false;
  EXPECT_FALSE(UsesLandmarks(QueryOn(pool[0], 0.95f), options));
  LandmarkRankOptions bad;
  bad.weight = -1;
  EXPECT_FALSE(bad.Check());
  bad = LandmarkRankOptions{};
  bad.min_presence = 2;
  EXPECT_FALSE(bad.Check());
}

// A search of either hand takes the hand the network names with confidence, from landmarks the
// re-ranking uses; a search of one hand, unsure or unused landmarks, or handedness 1 keep both.
TEST(LandmarkRankTest, TheNetworksHandednessChoosesTheHandSearched) {
  const std::vector<Match> pool = Pool();
  PictureEvidence q = QueryOn(pool[0], 0.95f);
  const LandmarkRankOptions options;
  auto with = [&](float handedness) {
    q.landmarks->handedness = handedness;
    return SearchedHand(q, Hand::kEither, options);
  };
  EXPECT_EQ(with(0.97f), Hand::kRight);
  EXPECT_EQ(with(0.03f), Hand::kLeft);
  EXPECT_EQ(with(0.9f), Hand::kEither);  // not above the threshold
  EXPECT_EQ(with(0.5f), Hand::kEither);
  EXPECT_EQ(with(-1.0f), Hand::kEither);  // the model has no handedness output
  q.landmarks->handedness = 0.03f;
  EXPECT_EQ(SearchedHand(q, Hand::kRight, options), Hand::kRight);
  LandmarkRankOptions both = options;
  both.handedness = 1;
  EXPECT_EQ(SearchedHand(q, Hand::kEither, both), Hand::kEither);
  q.landmarks->presence = 0.5f;  // below min_presence: the landmarks are not used
  EXPECT_EQ(SearchedHand(q, Hand::kEither, options), Hand::kEither);
  LandmarkRankOptions bad = options;
  bad.handedness = 0.4f;
  EXPECT_FALSE(bad.Check());
}

// Through a real search: without usable landmarks SearchEvidence is Search; with them the list
// is the pool's, re-ranked, and every match carries its score.
TEST(LandmarkRankTest, SearchEvidenceReranksThePoolSearch) {
  auto db = std::make_shared<const Database>(testing::SyntheticDatabase(60, 80, 8, 6));
  Searcher searcher(db);
  QueryEdges q;
  q.kind = QueryInputKind::kPhoto;
  q.points = testing::SyntheticEdgeSet(517, 80);  // not one of the views: every D_c > 0
  q.scale = 1;
  SearchOptions search;
  search.top_k = 5;
  search.num_threads = 1;
  auto plain = searcher.Search(q.points_px(), search);
  ASSERT_TRUE(plain.ok());
  PictureEvidence unsure_query = QueryOn((*plain)[3], 0.2f);
  unsure_query.edges.points = q.points;
  auto unsure = SearchEvidence(searcher, unsure_query, search, LandmarkRankOptions{});
  ASSERT_TRUE(unsure.ok());
  ASSERT_EQ(unsure->size(), plain->size());
  for (size_t i = 0; i < plain->size(); ++i) {
    EXPECT_EQ((*unsure)[i].view_id, (*plain)[i].view_id);
    EXPECT_EQ((*unsure)[i].roll, (*plain)[i].roll);
    EXPECT_EQ((*unsure)[i].score, -1.0);
  }
  PictureEvidence with = QueryOn((*plain)[3], 1.0f);
  with.edges.points = q.points;
  auto ranked = SearchEvidence(searcher, with, search, LandmarkRankOptions{});
  ASSERT_TRUE(ranked.ok());
  ASSERT_EQ(ranked->size(), 5u);
  int position = -1;
  for (size_t i = 0; i < ranked->size(); ++i) {
    const Match& m = (*ranked)[i];
    EXPECT_GE(m.landmark_error, 0.0);
    EXPECT_NEAR(m.score, m.distance / (*plain)[0].distance + m.landmark_error, 1e-9);
    if (i > 0) {
      EXPECT_LE((*ranked)[i - 1].score, m.score);
    }
    if (m.view_id == (*plain)[3].view_id && m.roll == (*plain)[3].roll) {
      position = static_cast<int>(i);
      EXPECT_NEAR(m.landmark_error, 0.0, 1e-5);
    }
  }
  // The match whose keypoints the landmarks sit on moved up from 4th.
  ASSERT_GE(position, 0);
  EXPECT_LT(position, 3);
  // Either hand asked, a left hand named: only left-hand matches.
  SearchOptions either = search;
  either.hand = Hand::kEither;
  with.landmarks->handedness = 0.02f;
  auto left = SearchEvidence(searcher, with, either, LandmarkRankOptions{});
  ASSERT_TRUE(left.ok());
  ASSERT_FALSE(left->empty());
  for (const Match& m : *left) EXPECT_EQ(m.hand, Hand::kLeft);
}

}  // namespace
}  // namespace handdb
