#include "pose/landmark_rank.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "query/top_k.h"

namespace handdb {
namespace {

// Half the normalised hand diameter (edges/normalise.h scales the silhouette to 192 px).
constexpr double kHandRadiusPx = 96.0;

}  // namespace

bool LandmarkRankOptions::Check() const {
  CHECK_OPTION(std::isfinite(weight));
  CHECK_OPTION_GE(weight, 0.0);
  CHECK_OPTION(min_presence >= 0.0f && min_presence <= 1.0f);
  CHECK_OPTION(handedness >= 0.5f && handedness <= 1.0f);
  CHECK_OPTION_GE(pool_views, 1);
  CHECK_OPTION_LE(pool_views, 100000);
  CHECK_OPTION_GE(pool_per_shape, 1);
  return true;
}

double LandmarkError(const PictureEvidence& picture, const Match& match) {
  THROW_CHECK(picture.landmarks.has_value());
  const QueryEdges& query = picture.edges;
  THROW_CHECK_GT(query.scale, 0.0);
  double sum = 0;
  for (int k = 0; k < kNumLandmarks; ++k) {
    const Point2f& p = picture.landmarks->image_px[k];
    // Into the normalised frame: the inverse of QueryEdges::ImageFromNormalised.
    const double x = (p.x - query.centre_x) * query.scale;
    const double y = (p.y - query.centre_y) * query.scale;
    sum += std::hypot(x - match.label.keypoints[k][0], y - match.label.keypoints[k][1]);
  }
  return sum / kNumLandmarks / kHandRadiusPx;
}

bool UsesLandmarks(const PictureEvidence& picture, const LandmarkRankOptions& options) {
  return options.enabled && picture.landmarks.has_value() &&
         picture.landmarks->presence >= options.min_presence && picture.edges.scale > 0;
}

std::vector<Match> RerankByLandmarks(std::vector<Match> pool,
                                     const PictureEvidence& picture,
                                     const SearchOptions& search,
                                     const LandmarkRankOptions& options) {
  if (pool.empty()) return pool;
  double best = pool.front().distance;
  for (const Match& m : pool) best = std::min(best, m.distance);
  for (Match& m : pool) {
    m.landmark_error = LandmarkError(picture, m);
    // A zero best D_c (the query is a view) ranks by the distance's excess instead of a ratio.
    m.score = (best > 0 ? m.distance / best : 1.0 + m.distance) + options.weight * m.landmark_error;
  }
  // Ties keep the D_c order (stable), so equal scores rank as the search did.
  std::stable_sort(
      pool.begin(), pool.end(), [](const Match& a, const Match& b) { return a.score < b.score; });
  return LimitPerShape(std::move(pool), search.top_k, search.max_per_shape);
}

Hand SearchedHand(const PictureEvidence& picture, Hand asked, const LandmarkRankOptions& options) {
  if (asked != Hand::kEither || !UsesLandmarks(picture, options)) return asked;
  const float h = picture.landmarks->handedness;
  if (h > options.handedness && h <= 1) return Hand::kRight;
  if (h >= 0 && h < 1 - options.handedness) return Hand::kLeft;
  return asked;
}

Result<std::vector<Match>> SearchEvidence(const Searcher& searcher,
                                          const PictureEvidence& picture,
                                          const SearchOptions& search,
                                          const LandmarkRankOptions& options,
                                          SearchStats* stats) {
  const std::vector<Point2f> points = picture.edges.points_px();
  if (!UsesLandmarks(picture, options)) return searcher.Search(points, search, stats);
  SearchOptions pool = search;
  pool.hand = SearchedHand(picture, search.hand, options);
  pool.top_k = std::max(search.top_k, options.pool_views);
  if (search.max_per_shape > 0) {
    pool.max_per_shape = std::max(search.max_per_shape, options.pool_per_shape);
  }
  auto matches = searcher.Search(points, pool, stats);
  if (!matches.ok()) return matches;
  return RerankByLandmarks(std::move(matches).value(), picture, search, options);
}

}  // namespace handdb
