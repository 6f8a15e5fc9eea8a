// The small synthetic database and the test views that the evaluation tests
// (evaluate/evaluate_test.cc, evaluate/parts_test.cc, evaluate/photos_test.cc) score against, so
// that they test one setup.
#pragma once

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>

#include "evaluate/evaluate.h"
#include "evaluate/metrics.h"
#include "format/roll.h"
#include "photo/image_edges.h"
#include "query/database.h"
#include "query/search_testing.h"

namespace handdb::testing {

// 40 synthetic views (10 per shape) of about 200 points, 12 rolls.
inline std::shared_ptr<const Database> EvalDatabase() {
  return std::make_shared<const Database>(SyntheticDatabase(40, 200, 12, 10));
}

// A test view whose truth is the pose of database view (v, r).
inline TestView ViewOf(const Database& db, uint32_t id, view_id_t v, roll_id_t r, bool basic) {
  TestView t;
  t.id = id;
  t.basic = basic;
  t.shape_name = "v" + std::to_string(v);
  t.truth = PoseFromLabel(db.label(v), RollAngle(r, db.num_rolls()));
  return t;
}

// A photo's query showing database view (v, r), mirrored (a left hand) when `mirrored`, in a
// picture where normalised px = (picture px - centre) * scale.
inline QueryEdges PhotoQueryOf(const Database& db,
                               view_id_t v,
                               roll_id_t r,
                               bool mirrored,
                               double centre_x,
                               double centre_y,
                               double scale) {
  QueryEdges q;
  q.kind = QueryInputKind::kPhoto;
  q.centre_x = centre_x;
  q.centre_y = centre_y;
  q.scale = scale;
  std::vector<Point2f> rolled;
  RollPoints(db.points(v), RollAngle(r, db.num_rolls()), &rolled);
  for (const Point2f& p : rolled) {
    q.points.push_back({static_cast<int16_t>(std::lround((mirrored ? -p.x : p.x) * kPointScale)),
                        static_cast<int16_t>(std::lround(p.y * kPointScale))});
  }
  return q;
}

}  // namespace handdb::testing
