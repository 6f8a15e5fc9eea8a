#include "pose/match_json.h"

#include <cmath>
#include <string>

#include "format/roll.h"

namespace handdb {
namespace {

constexpr double kDeg = 180.0 / M_PI;

}  // namespace

double RollDegrees0To360(double roll_rad) {
  double d = std::fmod(roll_rad * kDeg, 360.0);
  if (d < 0) d += 360.0;
  return d >= 360.0 ? 0.0 : d;
}

nlohmann::json MatchToJson(const Match& match, int rank, const QueryEdges* query) {
  using json = nlohmann::json;
  const ViewLabel& l = match.label;
  json kps = json::array();
  for (const auto& k : l.keypoints) kps.push_back({k[0], k[1], k[2]});
  json j = {{"rank", rank},
            {"view_id", match.view_id},
            {"roll", match.roll},
            {"roll_deg", RollDegrees0To360(match.roll_angle)},
            {"distance", match.distance},
            {"a", match.a},
            {"b", match.b},
            {"render_id", l.render_id},
            {"shape_id", l.shape_id},
            {"shape_name", match.shape_name},
            {"dir_id", l.dir_id},
            {"joint_angles", l.joint_angles},
            {"view_direction", l.view_direction},
            {"view_theta", l.view_theta},
            {"view_phi", l.view_phi},
            {"view_theta_deg", l.view_theta * kDeg},
            {"view_phi_deg", l.view_phi * kDeg},
            {"camera_roll", l.camera_roll},
            {"hand", std::string(HandName(match.hand))},
            {"keypoints", kps}};
  if (query != nullptr) {
    json kps_image = json::array();
    for (const auto& k : l.keypoints) {
      const Point2f p = query->ImageFromNormalised({k[0], k[1]});
      kps_image.push_back({p.x, p.y});
    }
    j["keypoints_image_px"] = kps_image;
  }
  if (match.score >= 0) {
    j["score"] = match.score;
    j["landmark_error"] = match.landmark_error;
  }
  return j;
}

nlohmann::json MatchFitToJson(const MatchFit& mf) {
  using json = nlohmann::json;
  if (!mf.fitted) return {{"fitted", false}, {"reason", mf.reason}};
  const PoseFit& f = mf.fit;
  json rotation = json::array();
  for (const Vec3d& row : f.cam_from_hand) rotation.push_back({row[0], row[1], row[2]});
  json kps = json::array();
  for (const auto& k : mf.keypoints_3d) kps.push_back({k[0], k[1], k[2]});
  json kps_image = json::array();
  for (const Point2f& p : mf.keypoints_image_px) kps_image.push_back({p.x, p.y});
  return {{"fitted", true},
          {"converged", f.converged},
          {"termination", f.termination},
          {"iterations", f.iterations},
          {"joint_angles", f.joints},
          {"view_direction", f.view_direction},
          {"camera_roll", f.roll},
          {"cam_from_hand", rotation},
          {"scale", f.scale},
          {"shift", f.shift},
          {"keypoints", kps},
          {"keypoints_image_px", kps_image},
          {"landmark_error_px",
           {{"start", mf.landmark_error_start_px}, {"fitted", mf.landmark_error_px}}},
          {"cost",
           {{"initial", f.initial_cost},
            {"final", f.final_cost},
            {"landmarks", f.landmark_cost},
            {"prior", f.prior_cost},
            {"silhouette", f.silhouette_cost}}}};
}

}  // namespace handdb
