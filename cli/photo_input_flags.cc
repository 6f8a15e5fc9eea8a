#include "cli/photo_input_flags.h"

#include <cstdio>
#include <exception>

#include "cli/cli_util.h"
#include "edges/view_conversion.h"
#include "format/manifest.h"

namespace handdb::cli {
namespace {

// "a,b,c,..." -> exactly n integers.
bool ParseInts(const std::string& text, size_t n, std::vector<int>* out) {
  out->clear();
  size_t pos = 0;
  while (pos <= text.size()) {
    const size_t comma = text.find(',', pos);
    const std::string item =
        text.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
    try {
      size_t used = 0;
      out->push_back(std::stoi(item, &used));
      if (used != item.size()) return false;
    } catch (const std::exception&) {
      return false;
    }
    if (comma == std::string::npos) break;
    pos = comma + 1;
  }
  return out->size() == n;
}

}  // namespace

void PhotoInputFlags::Add(CLI::App& app, Which which) {
  if (which.input) {
    app.add_option("--input",
                   input,
                   "kind of picture (auto: .exr -> labels, binary image -> edges, else photo)")
        ->check(CLI::IsMember({"auto", "photo", "edges", "labels"}))
        ->capture_default_str();
  }
  if (which.mask) {
    app.add_option(
        "--mask", mask, "photo: hand mask image, non-zero = hand (replaces skin colour)");
  }
  app.add_option("--roi", roi, "photo: x,y,w,h rectangle that contains the hand");
  app.add_option("--skin",
                 skin,
                 "photo: skin box Ymin,Ymax,Crmin,Crmax,Cbmin,Cbmax (YCrCb, 0..255; default "
                 "40,255,133,173,77,127)");
  app.add_option("--canny", canny, "photo: Canny thresholds low,high (default 40,120)");
  app.add_option("--contour-clearance",
                 options.picture.edges.contour_clearance_px,
                 "photo: drop Canny edges within this many px of the silhouette contour (0: keep)")
      ->check(CLI::Range(0, 20))
      ->capture_default_str();
  app.add_flag_callback(
      "--edges-outside",
      [this] { options.picture.edges.interior_edges_only = false; },
      "photo: also keep Canny edges up to 4 px outside the hand region");
  app.add_option("--work-diameter",
                 options.picture.edges.work_diameter_px,
                 "photo: resample the hand to this diameter in px before the mask clean-up and "
                 "Canny (0: the picture's own pixels)")
      ->check(CLI::Range(0.0, 4096.0))
      ->capture_default_str();
  app.add_flag_callback(
      "--no-wrist-cut",
      [this] { options.picture.edges.cut_forearm = false; },
      "photo: keep a forearm that leaves the picture (by default it is cut off at the wrist, "
      "docs/query.md)");
  app.add_option("--landmarks",
                 landmarks,
                 "photo: re-rank the nearest views by the hand landmarks a pretrained network "
                 "finds (docs/query.md): auto (the model scripts/deps.sh installs; D_c alone "
                 "with a warning if it is missing), off, or a .tflite model file")
      ->capture_default_str();
  app.add_option("--landmark-passes",
                 options.picture.landmark_passes,
                 "photo: runs of the landmark network: 1 (on the crop the segmentation gives) or "
                 "2 (then on the crop its joints give, MediaPipe's tracking crop; nearer fits, "
                 "one more run a photo)")
      ->check(CLI::Range(1, 2))
      ->capture_default_str();
  app.add_option("--landmark-handedness",
                 options.landmark_rank.handedness,
                 "photo, --hand either: search only the hand the landmark network names when its "
                 "handedness score is above this (right) or below 1 minus it (left); 1: always "
                 "both hands")
      ->check(CLI::Range(0.5, 1.0))
      ->capture_default_str();
  app.add_option("--landmark-weight",
                 options.landmark_rank.weight,
                 "photo: weight of the landmark fit against D_c / best D_c in the ranking")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
}

bool PhotoInputFlags::FinishFlags(const std::string& cmd) {
  const char* c = cmd.c_str();
  auto kind = ParseQueryInputKind(input);
  if (!kind.ok()) {
    std::fprintf(stderr,
                 "handdb %s: --input %s: a picture is read as auto, photo, edges or labels\n",
                 c,
                 input.c_str());
    return false;
  }
  options.picture.edges.kind = *kind;
  options.picture.edges.mask = mask;
  if (!roi.empty()) {
    auto r = ParsePixelRect(roi);
    if (!r.ok()) {
      std::fprintf(stderr, "handdb %s: --roi: %s\n", c, r.status().message().c_str());
      return false;
    }
    options.picture.edges.roi = *r;
  }
  std::vector<int> v;
  if (!skin.empty()) {
    if (!ParseInts(skin, 6, &v)) {
      std::fprintf(
          stderr, "handdb %s: --skin needs six integers Ymin,Ymax,Crmin,Crmax,Cbmin,Cbmax\n", c);
      return false;
    }
    for (int i = 0; i < 6; i += 2) {
      if (v[i] < 0 || v[i] > v[i + 1] || v[i + 1] > 255) {
        std::fprintf(stderr,
                     "handdb %s: --skin %s: each of Y, Cr, Cb needs 0 <= min <= max <= 255\n",
                     c,
                     skin.c_str());
        return false;
      }
    }
    options.picture.edges.skin = {v[0], v[1], v[2], v[3], v[4], v[5]};
  }
  if (!canny.empty()) {
    if (!ParseInts(canny, 2, &v)) {
      std::fprintf(stderr, "handdb %s: --canny needs two integers low,high\n", c);
      return false;
    }
    if (v[0] < 0 || v[0] > v[1]) {
      std::fprintf(stderr, "handdb %s: --canny %s: needs 0 <= low <= high\n", c, canny.c_str());
      return false;
    }
    options.picture.edges.canny_low = v[0];
    options.picture.edges.canny_high = v[1];
  }
  if (options.picture.edges.work_diameter_px != 0 && options.picture.edges.work_diameter_px < 16) {
    std::fprintf(stderr,
                 "handdb %s: --work-diameter %g: 0 (the picture's own pixels) or 16..4096 px\n",
                 c,
                 options.picture.edges.work_diameter_px);
    return false;
  }
  if (!options.picture.edges.Check()) {
    std::fprintf(stderr, "handdb %s: invalid photo options (see above)\n", c);
    return false;
  }
  return true;
}

bool PhotoInputFlags::Finish(const std::string& cmd) {
  return FinishFlags(cmd) && OpenLandmarker(cmd);
}

bool PhotoInputFlags::OpenLandmarker(const std::string& cmd) {
  const char* c = cmd.c_str();
  // Edge images and label EXRs have no photo to find landmarks in.
  if (options.picture.edges.kind != QueryInputKind::kEdges &&
      options.picture.edges.kind != QueryInputKind::kLabels &&
      !ResolveLandmarker(landmarks, cmd, &options.picture.landmarker)) {
    failure_exit_code = kExitError;
    return false;
  }
  options.landmark_rank.enabled = options.picture.landmarker != nullptr;
  if (!options.landmark_rank.Check()) {
    std::fprintf(stderr, "handdb %s: invalid landmark options (see above)\n", c);
    return false;
  }
  return true;
}

Status PhotoInputFlags::UseDatabaseConversion(const Database& db,
                                              const std::filesystem::path& db_dir) {
  auto recorded = DatabaseViewConversionFromMetadata(
      nlohmann::json::parse(db.manifest_metadata_json()), (db_dir / kManifestFileName).string());
  if (!recorded.ok()) return recorded.status();
  options.picture.edges.label_edges = recorded->edges;
  options.picture.edges.label_joint_pairs = recorded->joint_pairs;
  return Status::Ok();
}

std::vector<std::string> PhotoInputFlags::Args() const {
  std::vector<std::string> args = {"--input",
                                   input,
                                   "--contour-clearance",
                                   std::to_string(options.picture.edges.contour_clearance_px)};
  if (!roi.empty()) args.insert(args.end(), {"--roi", roi});
  if (!skin.empty()) args.insert(args.end(), {"--skin", skin});
  if (!canny.empty()) args.insert(args.end(), {"--canny", canny});
  if (!options.picture.edges.interior_edges_only) args.push_back("--edges-outside");
  args.insert(args.end(),
              {"--work-diameter", std::to_string(options.picture.edges.work_diameter_px)});
  if (!options.picture.edges.cut_forearm) args.push_back("--no-wrist-cut");
  // The model this process resolved, so every task uses the same one (or none).
  args.insert(args.end(),
              {"--landmarks",
               options.picture.landmarker ? options.picture.landmarker->path().string()
                                          : std::string("off"),
               "--landmark-passes",
               std::to_string(options.picture.landmark_passes),
               "--landmark-handedness",
               std::to_string(options.landmark_rank.handedness),
               "--landmark-weight",
               std::to_string(options.landmark_rank.weight)});
  return args;
}

nlohmann::json PhotoInputFlags::ToJson() const {
  const SkinModel& s = options.picture.edges.skin;
  const PixelRect& r = options.picture.edges.roi;
  return {
      {"input", std::string(QueryInputKindName(options.picture.edges.kind))},
      {"roi", r.empty() ? nlohmann::json(nullptr) : nlohmann::json{r.x, r.y, r.width, r.height}},
      {"skin", {s.y_min, s.y_max, s.cr_min, s.cr_max, s.cb_min, s.cb_max}},
      {"canny", {options.picture.edges.canny_low, options.picture.edges.canny_high}},
      {"contour_clearance_px", options.picture.edges.contour_clearance_px},
      {"interior_edges_only", options.picture.edges.interior_edges_only},
      {"work_diameter_px", options.picture.edges.work_diameter_px},
      {"cut_forearm", options.picture.edges.cut_forearm},
      {"landmarks",
       options.picture.landmarker ? nlohmann::json(options.picture.landmarker->path().string())
                                  : nlohmann::json(nullptr)},
      {"landmark_passes", options.picture.landmark_passes},
      {"landmark_handedness", options.landmark_rank.handedness},
      {"landmark_weight", options.landmark_rank.weight}};
}

bool ResolveLandmarker(const std::string& spec,
                       const std::string& cmd,
                       std::shared_ptr<const HandLandmarker>* out) {
  out->reset();
  if (spec == "off") return true;
  const bool automatic = spec == "auto";
  const std::filesystem::path model =
      automatic ? HandLandmarker::DefaultModelPath() : std::filesystem::path(spec);
  std::error_code ec;
  if (automatic && !std::filesystem::exists(model, ec)) {
    std::fprintf(stderr,
                 "handdb %s: warning: no hand landmark model at %s (scripts/deps.sh --asset "
                 "installs it): photos are ranked by D_c alone\n",
                 cmd.c_str(),
                 model.string().c_str());
    return true;
  }
  auto opened = HandLandmarker::Open(model);
  if (!opened.ok()) {
    std::fprintf(
        stderr, "handdb %s: --landmarks: %s\n", cmd.c_str(), opened.status().message().c_str());
    return false;
  }
  *out = std::move(opened).value();
  return true;
}

void HandFlag::Add(CLI::App& app, const std::string& what) {
  app.add_option("--hand",
                 name,
                 "which hand " + what +
                     " shows: right (the database's), left (mirrored before the search) or "
                     "either (both searched, one merged top-k)")
      ->check(CLI::IsMember({"right", "left", "either"}))
      ->capture_default_str();
}

}  // namespace handdb::cli
