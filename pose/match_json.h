// A match as JSON, written in one place: `handdb query --json`'s matches[]
// (schemas/query_result.schema.json) and Python's Match.to_dict() are this object, so the two
// cannot drift apart.
#pragma once

#include <nlohmann/json.hpp>

#include "photo/image_edges.h"
#include "pose/fit_matches.h"
#include "query/searcher.h"

namespace handdb {

// A roll angle (radians) in degrees in [0, 360), as the outputs print it.
double RollDegrees0To360(double roll_rad);

// The match at 1-based `rank`: its view, roll, distance, label and keypoints, score and
// landmark_error when landmarks re-ranked it, and keypoints_image_px (its keypoints in the
// query picture's pixels) when `query` is given (null: a query of bare points, no picture).
nlohmann::json MatchToJson(const Match& match, int rank, const QueryEdges* query);

// A match's pose fit (pose/fit_matches.h): the "fit" object of its match. Unfitted: fitted false
// and the reason; fitted: the fitted joints, camera, keypoints, costs and the solver's verdict.
nlohmann::json MatchFitToJson(const MatchFit& fit);

}  // namespace handdb
