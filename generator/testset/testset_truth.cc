// The ground truth of a rendered test set (generator/testset/testset.h): label renders converted
// exactly as the database converter does. Kept apart from testset.cc, which includes the hand-model
// and sampler headers.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "base/json_schema.h"
#include "base/progress.h"
#include "base/thread_pool.h"
#include "edges/exr_io.h"
#include "generator/convert/converter.h"
#include "generator/testset/testset.h"
#include "handdb_version.h"

namespace handdb {
namespace fs = std::filesystem;

fs::path SequenceFramePath(const fs::path& dir, uint32_t sequence, uint32_t frame) {
  char name[64];
  std::snprintf(name, sizeof name, "s%03u/%06u.png", sequence, frame);
  return dir / "sequences" / name;
}

namespace {

// DIR/sequences/sNNN/NNNNNN.png -> ../../photos/uNNNNN/rNNNNNN.png for every photographed frame.
// Relative links keep the folder valid when DIR is moved or copied with its links; a link left
// by an earlier run is replaced only when it points elsewhere.
Status WriteSequenceFolders(const fs::path& dir, const TestSetPlan& plan) {
  for (const TestSetItem& item : plan.items) {
    if (!item.sequence) continue;
    const fs::path photo = TestSetPhotoPath(dir, item.unit, item.id);
    if (!fs::exists(photo)) continue;
    const fs::path link = SequenceFramePath(dir, item.sequence->sequence, item.sequence->frame);
    const fs::path target = fs::path("..") / ".." / fs::relative(photo, dir);
    std::error_code ec;
    fs::create_directories(link.parent_path(), ec);
    if (ec) return Status(StatusCode::kIoError, link.parent_path().string() + ": " + ec.message());
    if (fs::is_symlink(fs::symlink_status(link, ec))) {
      if (fs::read_symlink(link, ec) == target) continue;
      fs::remove(link, ec);
    }
    fs::create_symlink(target, link, ec);
    if (ec) return Status(StatusCode::kIoError, link.string() + ": " + ec.message());
  }
  return Status::Ok();
}

}  // namespace

Status WriteTestSetGroundTruth(const fs::path& dir, int num_threads, bool progress_enabled) {
  auto plan = ReadTestSetPlan(dir / "testset_plan.json");
  if (!plan.ok()) return plan.status();
  const size_t n = plan->items.size();
  std::vector<nlohmann::json> items(n);
  std::vector<Status> errors(n);
  const ViewConversionOptions conversion;
  ExrReadOptions read_options;
  read_options.expected_width = plan->resolution;
  read_options.expected_height = plan->resolution;
  Progress progress("testset truth", n, progress_enabled, "views");
  // Every item is converted (no stop at the first bad one) so the error names how many are bad.
  ParallelFor(n, ResolveNumThreads(num_threads), [&](size_t i, int) {
    const TestSetItem& item = plan->items[i];
    const fs::path exr = TestSetLabelPath(dir, item.unit, item.id);
    const fs::path sidecar_path = TestSetSidecarPath(dir, item.unit, item.id);
    auto image = ReadLabelExr(exr, read_options);
    if (!image.ok()) {
      errors[i] = image.status();
      return true;
    }
    auto sidecar = ReadSidecar(sidecar_path);
    if (!sidecar.ok()) {
      errors[i] = sidecar.status();
      return true;
    }
    // The render must be of this item.
    double joint_diff = 0;
    for (int k = 0; k < kNumJointAngles; ++k) {
      joint_diff = std::max(joint_diff, std::abs(sidecar->joint_angles[k] - item.joints[k]));
    }
    const double roll_diff = std::abs(std::remainder(sidecar->camera_roll - item.roll, 2 * M_PI));
    if (sidecar->render_id != item.id || joint_diff > 1e-5 || roll_diff > 1e-5) {
      errors[i] = Status(
          StatusCode::kSizeMismatch,
          sidecar_path.string() + ": sidecar does not match plan item " + std::to_string(item.id) +
              " (render_id " + std::to_string(sidecar->render_id) + ", joint difference " +
              std::to_string(joint_diff) + ", roll difference " + std::to_string(roll_diff) + ")");
      return true;
    }
    auto view = ConvertView(*image, *sidecar, conversion, exr.string());
    if (!view.ok()) {
      errors[i] = view.status();
      return true;
    }
    const ViewLabel& label = view->label;
    nlohmann::json keypoints = nlohmann::json::array();
    for (const auto& k : label.keypoints) keypoints.push_back({k[0], k[1], k[2]});
    nlohmann::json j = {
        {"id", item.id},
        {"unit", item.unit},
        {"basic", item.basic},
        {"shape_name", item.shape_name},
        {"joint_angles", nlohmann::json(item.joints)},
        {"view_direction", item.direction},
        {"view_theta", item.theta},
        {"view_phi", item.phi},
        {"camera_roll", item.roll},
        {"keypoints", keypoints},
        {"normalisation",
         {{"centre_px", {label.source_centre_px[0], label.source_centre_px[1]}},
          {"diameter_px", label.source_diameter_px},
          {"scale", label.scale}}},
        {"num_edge_points", view->points.size()},
        {"label", fs::relative(exr, dir).generic_string()},
        {"sidecar", fs::relative(sidecar_path, dir).generic_string()},
    };
    const fs::path photo = TestSetPhotoPath(dir, item.unit, item.id);
    if (fs::exists(photo)) j["photo"] = fs::relative(photo, dir).generic_string();
    // Per item only when the plan draws the forearm per item; otherwise the set's "forearm" says.
    if (plan->doc.at("photo").contains("forearm_fraction")) j["forearm"] = item.forearm;
    if (item.sequence) {
      // The photo shows the label render's hand shifted by the offset: the same camera.
      nlohmann::json px = nlohmann::json::array();
      int in_picture = 0;
      for (const auto& k : sidecar->keypoints_px) {
        const double x = k[0] + item.photo_offset_px[0];
        const double y = k[1] + item.photo_offset_px[1];
        px.push_back({x, y});
        in_picture += (x >= 0 && y >= 0 && x < plan->resolution && y < plan->resolution) ? 1 : 0;
      }
      j["sequence"] = {{"id", item.sequence->sequence},
                       {"frame", item.sequence->frame},
                       {"time", item.sequence->time},
                       {"clutter", item.clutter},
                       {"offset_px", item.photo_offset_px},
                       {"keypoints_px", px},
                       {"in_picture", in_picture},
                       {"visible", in_picture == kNumKeypoints}};
      if (j.contains("photo")) {
        j["sequence"]["frame_file"] =
            SequenceFramePath(fs::path(), item.sequence->sequence, item.sequence->frame)
                .generic_string();
      }
    }
    items[i] = std::move(j);
    progress.Add();
    return true;
  });
  progress.Finish();
  size_t bad = 0;
  Status first;
  for (const Status& s : errors) {
    if (!s.ok()) {
      if (first.ok()) first = s;
      ++bad;
    }
  }
  if (!first.ok()) {
    return Status(
        first.code(),
        first.message() +
            (bad > 1 ? " (and " + std::to_string(bad - 1) + " more bad test views)" : ""));
  }
  HANDDB_RETURN_IF_ERROR(WriteSequenceFolders(dir, *plan));
  nlohmann::json truth = {
      {"format", "handdb-testset"},
      {"version", kTestSetFormatVersion},
      {"name", plan->name},
      {"seed", plan->seed},
      {"plan", "testset_plan.json"},
      {"hand_model", plan->doc.at("hand_model")},
      {"forward_axis", plan->forward_axis},
      {"palm_normal", plan->palm_normal},
      {"resolution", plan->resolution},
      {"ortho_scale", plan->ortho_scale},
      {"clutter", plan->photo.clutter},
      {"handdb_version", HANDDB_VERSION},
      {"items", items},
  };
  if (plan->photo.forearm) truth["forearm"] = true;
  if (plan->doc.contains("sequence")) truth["sequence"] = plan->doc.at("sequence");
  HANDDB_RETURN_IF_ERROR(
      ValidateJson(truth, "testset.schema.json", (dir / "testset.json").string()));
  return WriteJsonFileAtomic(dir / "testset.json", truth);
}

}  // namespace handdb
