#include "track/neighbourhood.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <tuple>
#include <vector>

namespace handdb {
namespace {

constexpr uint32_t kShapes = 3;
constexpr uint32_t kDirections = 12;  // a ring of directions 30 degrees apart
constexpr uint32_t kRolls = 16;

// View s * kDirections + d: shape s (joint angles s * 0.3), direction d at phi = 30 d degrees on
// the equator; its hand axis points up, except view 1's, which is turned 2 roll steps.
Database RingDatabase() {
  std::vector<ViewLabel> labels;
  std::vector<std::vector<PointQ>> points;
  for (uint32_t s = 0; s < kShapes; ++s) {
    for (uint32_t d = 0; d < kDirections; ++d) {
      ViewLabel l;
      l.shape_id = s;
      l.dir_id = d;
      l.joint_angles.fill(0.3f * s);
      const double phi = d * M_PI / 6;
      l.view_direction = {static_cast<float>(std::cos(phi)), static_cast<float>(std::sin(phi)), 0};
      double axis = -M_PI / 2;
      if (s == 0 && d == 1) axis += 2 * 2 * M_PI / kRolls;
      l.keypoints[0] = {0, 0, 0};
      l.keypoints[9] = {
          static_cast<float>(50 * std::cos(axis)), static_cast<float>(50 * std::sin(axis)), 0};
      labels.push_back(l);
      points.push_back({{0, 0}, {16, 16}});
    }
  }
  return Database::FromMemory(std::move(labels), std::move(points), kRolls);
}

std::set<std::tuple<uint32_t, uint32_t>> Pairs(const std::vector<SearchPair>& pairs, Hand hand) {
  std::set<std::tuple<uint32_t, uint32_t>> out;
  for (const SearchPair& p : pairs) {
    EXPECT_EQ(p.hand, hand);
    out.insert({p.view, p.roll});
  }
  EXPECT_EQ(out.size(), pairs.size()) << "a pair twice";
  return out;
}

Match At(view_id_t v, roll_id_t r, Hand hand = Hand::kRight) {
  Match m;
  m.view_id = v;
  m.roll = r;
  m.hand = hand;
  return m;
}

TEST(ViewNeighbourhood, DirectionsWithinTheAngleRollsWithinTheSteps) {
  const Database db = RingDatabase();
  const ViewNeighbourhood nb(db);
  NeighbourhoodOptions o;
  o.direction_deg = 35;
  o.roll_steps = 1;
  // Shape 1, direction 0: directions 11, 0, 1 of every shape, rolls 2..4 (view 1 of shape 0 is
  // turned 2 steps: its rolls are centred on 1).
  const auto got = Pairs(nb.Near(At(kDirections + 0, 3, Hand::kLeft), o), Hand::kLeft);
  std::set<std::tuple<uint32_t, uint32_t>> want;
  for (uint32_t s = 0; s < kShapes; ++s) {
    for (uint32_t d : {11u, 0u, 1u}) {
      const int centre = s == 0 && d == 1 ? 1 : 3;
      for (int r = centre - 1; r <= centre + 1; ++r) want.insert({s * kDirections + d, r});
    }
  }
  EXPECT_EQ(got, want);
}

TEST(ViewNeighbourhood, JointRadiusKeepsNearShapesAndRollsWrapAround) {
  const Database db = RingDatabase();
  const ViewNeighbourhood nb(db);
  NeighbourhoodOptions o;
  o.direction_deg = 5;
  o.roll_steps = 2;
  o.joint_radius = 0;  // the same joint angles: the previous view's shape only
  const auto got = Pairs(nb.Near(At(kDirections + 4, 0), o), Hand::kRight);
  const std::set<std::tuple<uint32_t, uint32_t>> want = {{kDirections + 4, 14},
                                                         {kDirections + 4, 15},
                                                         {kDirections + 4, 0},
                                                         {kDirections + 4, 1},
                                                         {kDirections + 4, 2}};
  EXPECT_EQ(got, want);
  o.joint_radius = 0.35;  // shapes 0.3 apart: shapes 0, 1 and 2 are all within of shape 1
  EXPECT_EQ(nb.Near(At(kDirections + 4, 0), o).size(), 3u * 5u);
  EXPECT_EQ(nb.Near(At(4, 0), o).size(), 2u * 5u);  // shape 0: shapes 0 and 1
}

TEST(ViewNeighbourhood, OptionsCheck) {
  EXPECT_TRUE(NeighbourhoodOptions{}.Check());
  NeighbourhoodOptions o;
  o.direction_deg = 190;
  EXPECT_FALSE(o.Check());
  o = {};
  o.roll_steps = -1;
  EXPECT_FALSE(o.Check());
}

}  // namespace
}  // namespace handdb
