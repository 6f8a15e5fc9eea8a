// The hand's skeleton for drawing a pose over a picture (contact sheets): keypoint pairs in the
// order of docs/conventions.md (0 wrist, then 4 per finger from thumb to little finger, base to
// tip): the wrist to each fingertip, then across the knuckles.
#pragma once

#include <array>

namespace handdb {

constexpr std::array<std::array<int, 2>, 23> kSkeletonBones = {
    {{0, 1},  {1, 2},   {2, 3},   {3, 4},   {0, 5},  {5, 6},   {6, 7},   {7, 8},
     {0, 9},  {9, 10},  {10, 11}, {11, 12}, {0, 13}, {13, 14}, {14, 15}, {15, 16},
     {0, 17}, {17, 18}, {18, 19}, {19, 20}, {5, 9},  {9, 13},  {13, 17}}};

}  // namespace handdb
