#include "track/track_json.h"

#include "pose/match_json.h"

namespace handdb {

nlohmann::json TrackFrameToJson(const TrackFrame& frame) {
  using json = nlohmann::json;
  json j = {{"frame", frame.index},
            {"time_s", frame.time_s},
            {"source", frame.source},
            {"found", std::string(FoundByName(frame.found))}};
  if (frame.found == FoundBy::kNone) {
    j["error"] = frame.error.message();
    j["code"] = std::string(StatusCodeName(frame.error.code()));
  }
  const QueryEdges* edges = frame.evidence ? &frame.evidence->edges : nullptr;
  json matches = json::array();
  for (size_t i = 0; i < frame.matches.size(); ++i) {
    matches.push_back(MatchToJson(frame.matches[i], static_cast<int>(i) + 1, edges));
  }
  j["matches"] = std::move(matches);
  if (frame.chosen >= 0 && frame.has_pose) {
    const Match& m = frame.matches[frame.chosen];
    json kps = json::array();
    for (const Point2f& p : frame.keypoints_image_px) kps.push_back({p.x, p.y});
    json kps_3d = json::array();
    for (const auto& p : frame.keypoints_3d) kps_3d.push_back({p[0], p[1], p[2]});
    json pose = {{"match", frame.chosen + 1},
                 {"view_id", m.view_id},
                 {"roll", m.roll},
                 {"hand", std::string(HandName(m.hand))},
                 {"shape_name", m.shape_name},
                 {"distance", m.distance},
                 {"joint_angles", m.label.joint_angles},
                 {"view_direction", m.label.view_direction},
                 {"keypoints_image_px", std::move(kps)},
                 {"keypoints_3d", std::move(kps_3d)}};
    if (!frame.fit.fits.empty()) pose["fit"] = MatchFitToJson(frame.fit.fits.front());
    j["pose"] = std::move(pose);
  }
  j["landmarks_used"] = frame.landmarks_used;
  j["search"] = {{"pairs", frame.pairs_searched}, {"seconds", frame.search_seconds}};
  j["seconds"] = frame.seconds;
  return j;
}

}  // namespace handdb
