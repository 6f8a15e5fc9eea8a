// `handdb query DB IMAGE...`: the top-k database views for a picture of a hand, or for each of a
// batch of pictures searched with one open database.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <filesystem>
#include <future>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <system_error>
#include <type_traits>
#include <utility>
#include <vector>

#include "base/json_schema.h"
#include "base/progress.h"
#include "base/thread_pool.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/photo_input_flags.h"
#include "cli/query_batch.h"
#include "format/roll.h"
#include "generator/hand/camera.h"
#include "generator/hand/database_rig.h"
#include "handdb_version.h"
#include "photo/image_edges.h"
#include "pose/export_gltf.h"
#include "pose/fit.h"
#include "pose/landmark_rank.h"
#include "pose/match_json.h"
#include "pose/picture_search.h"
#include "pose/sheet.h"
#include "query/searcher.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr double kDeg = 180.0 / M_PI;
// Pictures up to which a batch opens the database as a single query does (few_queries).
constexpr size_t kFewPictures = 4;

// fn() on a thread of its own when `background`, else (or when the system refuses a thread)
// when the future is waited for: a deferred fn that is never waited for never runs.
template <typename Fn>
std::future<std::invoke_result_t<Fn>> InBackground(bool background, Fn fn) {
  if (background) {
    try {
      return std::async(std::launch::async, fn);
    } catch (const std::system_error&) {
    }
  }
  return std::async(std::launch::deferred, std::move(fn));
}

// printf into a string: a batch formats pictures on many threads and prints them in order.
[[gnu::format(printf, 2, 3)]] void Appendf(std::string* out, const char* format, ...) {
  va_list args;
  va_start(args, format);
  va_list again;
  va_copy(again, args);
  const int n = std::vsnprintf(nullptr, 0, format, args);
  va_end(args);
  if (n > 0) {
    const size_t old = out->size();
    out->resize(old + static_cast<size_t>(n) + 1);
    std::vsnprintf(out->data() + old, static_cast<size_t>(n) + 1, format, again);
    out->resize(old + static_cast<size_t>(n));
  }
  va_end(again);
}

std::string FormatTable(const std::vector<Match>& matches,
                        const PictureEvidence& picture,
                        const SearchStats& st,
                        const Database& db) {
  std::string out;
  const QueryEdges& q = picture.edges;
  Appendf(
      &out,
      "query: %zu edge points (%s, %dx%d, hand diameter %.1f px%s)%s\n",
      q.points.size(),
      std::string(QueryInputKindName(q.kind)).c_str(),
      q.width,
      q.height,
      q.diameter_px,
      q.forearm_cut ? ", forearm cut at the wrist" : "",
      q.touches_border && !q.forearm_cut ? "  [warning: the hand touches the image border]" : "");
  if (picture.landmarks) {
    const bool used = !matches.empty() && matches.front().score >= 0;
    Appendf(&out,
            "hand landmarks: presence %.3f, %s\n",
            static_cast<double>(picture.landmarks->presence),
            used ? "the nearest views re-ranked by D_c / best D_c + weight x landmark error "
                   "(column lm, in hand radii)"
                 : "below the 0.9 the ranking needs: ranked by D_c alone");
  }
  Appendf(&out,
          "database: %zu views x %u rolls = %llu virtual views; exact D_c for %llu (%.2f%%), "
          "%.1f ms\n\n",
          db.num_views(),
          db.num_rolls(),
          static_cast<unsigned long long>(st.virtual_views),
          static_cast<unsigned long long>(st.refined),
          st.virtual_views
              ? 100.0 * static_cast<double>(st.refined) / static_cast<double>(st.virtual_views)
              : 0.0,
          st.seconds_total * 1e3);
  if (st.candidates > 0) {
    Appendf(&out,
            "indexed search: %llu candidate pairs from the index (%.1f ms), the top %s exact "
            "among them (--search exact: every pair)\n\n",
            static_cast<unsigned long long>(st.candidates),
            st.seconds_index * 1e3,
            "k");
  }
  // Key joint angles: the flexion of each finger's base joint (thumb CMC, index..pinky MCP).
  Appendf(&out,
          "%4s  %8s  %5s  %-16s  %-5s  %7s %7s  %6s  %29s\n",
          "rank",
          "D_c",
          "lm",
          "shape",
          "hand",
          "theta",
          "phi",
          "roll",
          "base flexion T/I/M/R/P (deg)");
  int rank = 1;
  for (const Match& m : matches) {
    const ViewLabel& l = m.label;
    const std::string shape =
        m.shape_name.empty() ? "#" + std::to_string(l.shape_id) : m.shape_name;
    char lm[16] = "-";
    if (m.landmark_error >= 0) std::snprintf(lm, sizeof(lm), "%.3f", m.landmark_error);
    Appendf(&out,
            "%4d  %8.3f  %5s  %-16.16s  %-5s  %7.1f %7.1f  %6.1f  %5.0f %5.0f %5.0f %5.0f %5.0f\n",
            rank++,
            m.distance,
            lm,
            shape.c_str(),
            std::string(HandName(m.hand)).c_str(),
            l.view_theta * kDeg,
            l.view_phi * kDeg,
            RollDegrees0To360(m.roll_angle),
            l.joint_angles[0] * kDeg,
            l.joint_angles[4] * kDeg,
            l.joint_angles[8] * kDeg,
            l.joint_angles[12] * kDeg,
            l.joint_angles[16] * kDeg);
  }
  return out;
}

// The fitted pose under the table: from which match, how far the keypoints moved towards the
// landmarks, and the solver's verdict.
std::string FormatFit(const PictureFit& fit) {
  if (fit.fits.empty()) return "";
  char line[256];
  if (fit.best < 0) {
    std::snprintf(line, sizeof(line), "\npose fit: none (%s)\n", fit.fits.front().reason.c_str());
    return line;
  }
  const MatchFit& f = fit.fits[fit.best];
  std::snprintf(line,
                sizeof(line),
                "\nfitted pose (from match %d of %zu fitted): landmark error %.2f -> %.2f px "
                "(normalised), %s after %d iterations\n  joints (deg):",
                fit.best + 1,
                fit.fits.size(),
                f.landmark_error_start_px,
                f.landmark_error_px,
                f.fit.termination.c_str(),
                f.fit.iterations);
  std::string out = line;
  for (double a : f.fit.joints) {
    std::snprintf(line, sizeof(line), " %.0f", a * kDeg);
    out += line;
  }
  return out + "\n";
}

// The flags of `handdb query`, bound to the option structs they set.
struct QueryFlags {
  std::string db_dir, sheet, export_glb;
  std::shared_ptr<const DatabaseRig> rig;  // with --fit or --export: the database's rig
  // One picture, or a batch (IsBatch): several, a directory's pictures, "-" (a list on stdin).
  std::vector<std::string> images;
  bool batch = false;  // --batch, or IsBatch(images): set by Finish
  HandFlag hand;
  std::string search_mode = "auto";  // IndexUse: auto attaches the index the manifest lists
  std::string kdtree = std::string(KdTreeBackendName(SearchOptions{}.kdtree));
  bool as_json = false, verify = false, quiet = false;
  std::string fit = "auto";  // auto: fit when the database carries its rig
  // The search flags are bound to picture.options.search: one options struct for the picture,
  // its search and the landmark re-ranking (pose/picture_search.h).
  PhotoInputFlags picture;
  void Add(CLI::App& app);
  // Completes picture.options from the text flags; false (message printed) on bad usage.
  bool Finish();
};

void QueryFlags::Add(CLI::App& app) {
  SearchOptions& search = picture.options.search;
  app.add_option("DB", db_dir, "database directory (manifest.json + shards)")->required();
  app.add_option("IMAGE",
                 images,
                 "query image: photo, edge image or label EXR; several, a directory (its picture "
                 "files, sorted) or - (paths on stdin, one per line) search them all with one "
                 "database open")
      ->required();
  app.add_option("--top", search.top_k, "number of matches")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_option("--per-shape",
                 search.max_per_shape,
                 "at most this many matches per basic shape (0: no limit); 1 ranks shapes: "
                 "the --top nearest shapes, each by its best view")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  app.add_flag("--json",
               as_json,
               "print the result as JSON (schemas/query_result.schema.json); a batch prints one "
               "line per picture (JSON Lines, schemas/query_batch_line.schema.json)");
  app.add_flag("--batch",
               batch,
               "print as a batch even for one picture: JSON Lines with --json, a header line "
               "naming the picture above each table");
  app.add_option("--export",
                 export_glb,
                 "write the answer's pose as a glTF binary (.glb) of the posed hand asset with "
                 "its camera, for Blender or a web viewer: the fitted pose, else the top match's "
                 "stored pose (one picture only)");
  app.add_option("--sheet",
                 sheet,
                 "write a contact sheet PNG: input, its edges, the top matches (one picture only)");
  app.add_option("--threads",
                 search.num_threads,
                 "worker threads (-1: all cores); a batch searches its pictures in parallel "
                 "within this bound")
      ->capture_default_str();
  hand.Add(app, "IMAGE");
  app.add_flag("--bruteforce",
               search.brute_force,
               "exact D_c for every (view, roll), no pruning (the reference)");
  app.add_option("--kdtree", kdtree, "kd-tree backend")
      ->check(CLI::IsMember({"nanoflann", "pcl"}))
      ->capture_default_str();
  app.add_option(
         "--dt-cell", search.dt_cell_px, "distance-transform grid step in px (1, 0.5, 0.25, ...)")
      ->capture_default_str();
  app.add_flag_callback(
      "--no-coarse-bound",
      [&search] { search.coarse_bound = false; },
      "prune with the view -> query bound alone, without the coarse query -> view bound (for "
      "comparison: the results are identical)");
  picture.Add(app, PhotoInputFlags::Which{});
  app.add_flag("--verify", verify, "hash every shard section before searching");
  app.add_option("--search",
                 search_mode,
                 "exact: every (view, roll) pair; indexed: candidates from the database's index "
                 "(handdb index), then exact D_c of those only (docs/index.md); auto: indexed "
                 "when the database has an index")
      ->check(CLI::IsMember({"auto", "exact", "indexed"}))
      ->capture_default_str();
  app.add_option("--candidates",
                 search.index.candidates,
                 "indexed search: (view, roll) pairs refined exactly, per hand searched")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--nprobe",
                 search.index.nprobe,
                 "indexed search: IVF lists searched per rolled query (0: every view, one "
                 "batched scan of all rolls)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--fit",
                 fit,
                 "fit the pose of the first --fit-matches matches to the picture's hand landmarks "
                 "(pose/fit_matches.h): joint angles, rotation and keypoints off the database's "
                 "grid; auto: when the database carries its rig (hand_model.json); on: also a "
                 "picture without landmarks, to its silhouette; off: the stored views alone")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->capture_default_str();
  app.add_option(
         "--fit-matches",
         picture.options.fit.max_matches,
         "fit this many of the first matches (each reported beside its match); the pose is the "
         "fit of least final cost")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_flag("--quiet,-q",
               quiet,
               "no progress line (otherwise one on stderr once a search runs 1 s on a "
               "terminal, 5 s otherwise; for a batch, once it runs 1 s on a terminal)");
}

bool QueryFlags::Finish() {
  SearchOptions& search = picture.options.search;
  search.progress = !quiet;
  if (search.num_threads == 0 || search.num_threads < -1 || search.num_threads > MaxNumThreads()) {
    std::fprintf(stderr,
                 "handdb query: --threads %d: must be -1 or 1..%d (4x the cores, at most 256)\n",
                 search.num_threads,
                 MaxNumThreads());
    return false;
  }
  batch = batch || IsBatch(images);
  if (batch && !sheet.empty()) {
    std::fprintf(stderr,
                 "handdb query: --sheet writes the contact sheet of one picture: give one IMAGE\n");
    return false;
  }
  if (batch && !export_glb.empty()) {
    std::fprintf(stderr, "handdb query: --export writes the pose of one picture: give one IMAGE\n");
    return false;
  }
  if (batch && !picture.mask.empty()) {
    std::fprintf(stderr, "handdb query: --mask belongs to one photo: give one IMAGE\n");
    return false;
  }
  // The landmark model is loaded by RunQuery while the database opens (OpenLandmarker).
  if (!picture.FinishFlags("query")) return false;
  // One line naming the flag for what the flags can get wrong (the option checks below print
  // source paths); they stay as the backstop for the rest.
  bool dt_cell_ok = false;
  for (int k = 0; k <= 4; ++k) dt_cell_ok |= search.dt_cell_px == 1.0f / static_cast<float>(1 << k);
  if (!dt_cell_ok) {
    std::fprintf(stderr,
                 "handdb query: --dt-cell %g: must be 1, 0.5, 0.25, 0.125 or 0.0625 (px)\n",
                 static_cast<double>(search.dt_cell_px));
    return false;
  }
  search.kdtree = *ParseKdTreeBackend(kdtree);
  if (const Status backend = LoadKdTreeBackend(search.kdtree); !backend.ok()) {
    std::fprintf(
        stderr, "handdb query: --kdtree %s: %s\n", kdtree.c_str(), backend.message().c_str());
    picture.failure_exit_code = kExitError;
    return false;
  }
  search.hand = hand.Get();
  if (!search.Check()) {
    std::fprintf(stderr, "handdb query: invalid search options (see above)\n");
    return false;
  }
  return true;
}

// The contact sheet of --sheet: the input, its edges and each match's edges at its roll.
Status WriteSheet(const QueryFlags& flags,
                  const std::string& image,
                  const PictureEvidence& picture,
                  const std::vector<Match>& matches,
                  const PictureFit& fit,
                  const Database& db) {
  std::vector<SheetTile> tiles;
  int rank = 1;
  for (const Match& m : matches) {
    SheetTile t;
    char caption[128];
    // Re-ranked by landmarks: the score the order follows, then D_c.
    char score[32] = "";
    if (m.score >= 0) std::snprintf(score, sizeof(score), "s=%.2f ", m.score);
    std::snprintf(caption,
                  sizeof(caption),
                  "#%d  %sD=%.2f  %s  r=%.0f%s",
                  rank++,
                  score,
                  m.distance,
                  m.shape_name.empty() ? ("shape " + std::to_string(m.label.shape_id)).c_str()
                                       : m.shape_name.c_str(),
                  RollDegrees0To360(m.roll_angle),
                  m.hand == Hand::kLeft ? "  left" : "");
    t.caption = caption;
    std::vector<Point2f> rolled;
    RollPoints(db.points(m.view_id), m.roll_angle, &rolled);
    // A left-hand match is the mirror image of the view: draw it in the query's frame.
    const float mirror = m.hand == Hand::kLeft ? -1.0f : 1.0f;
    for (const Point2f& p : rolled) {
      t.points.push_back({static_cast<int16_t>(std::lround(mirror * p.x * kPointScale)),
                          static_cast<int16_t>(std::lround(p.y * kPointScale))});
    }
    tiles.push_back(std::move(t));
  }
  // The fitted pose's skeleton over the input picture, else the top match's: where --json's
  // pose / first match put their keypoints_image_px.
  std::vector<Point2f> skeleton;
  if (fit.best >= 0) {
    const auto& k = fit.fits[fit.best].keypoints_image_px;
    skeleton.assign(k.begin(), k.end());
  } else if (!matches.empty()) {
    for (const auto& k : matches.front().label.keypoints) {
      skeleton.push_back(picture.edges.ImageFromNormalised({k[0], k[1]}));
    }
  }
  return WriteContactSheet(flags.sheet, image, picture, tiles, ContactSheetOptions{}, skeleton);
}

// The --json document (schemas/query_result.schema.json).
json ResultJson(const QueryFlags& flags,
                const std::string& image,
                const PictureEvidence& picture,
                const std::vector<Match>& matches,
                const PictureFit& fit,
                const SearchStats& stats,
                const Database& db) {
  const QueryEdges& query = picture.edges;
  json matches_json = json::array();
  for (size_t i = 0; i < matches.size(); ++i) {
    json m = MatchToJson(matches[i], static_cast<int>(i) + 1, &query);
    if (i < fit.fits.size()) m["fit"] = MatchFitToJson(fit.fits[i]);
    matches_json.push_back(std::move(m));
  }
  const SearchOptions& search = flags.picture.options.search;
  json query_json = {{"edge_points", query.points.size()},
                     {"width", query.width},
                     {"height", query.height},
                     {"hand_pixels", query.hand_pixels},
                     {"touches_border", query.touches_border},
                     {"diameter_px", query.diameter_px},
                     {"centre_px", {query.centre_x, query.centre_y}},
                     {"scale", query.scale}};
  if (query.kind == QueryInputKind::kPhoto) {
    query_json["work_scale"] = query.work_scale;
    query_json["forearm_cut"] = query.forearm_cut;
    if (query.palm_radius_px > 0) {
      query_json["palm"] = {{"centre_px", {query.palm_centre_x, query.palm_centre_y}},
                            {"radius_px", query.palm_radius_px}};
    }
    if (query.forearm_cut) {
      query_json["wrist_line_px"] = {{query.wrist_line[0], query.wrist_line[1]},
                                     {query.wrist_line[2], query.wrist_line[3]}};
    }
    if (query.arm_found) query_json["arm_direction"] = {query.arm_dir_x, query.arm_dir_y};
    if (picture.landmarks) {
      const HandLandmarks& l = *picture.landmarks;
      json px = json::array();
      for (const Point2f& p : l.image_px) px.push_back({p.x, p.y});
      query_json["landmarks"] = {
          {"model", flags.picture.options.picture.landmarker->path().string()},
          {"passes", flags.picture.options.picture.landmark_passes},
          {"presence", l.presence},
          {"handedness", l.handedness},
          {"used", UsesLandmarks(picture, flags.picture.options.landmark_rank)},
          {"weight", flags.picture.options.landmark_rank.weight},
          {"image_px", px},
          {"crop",
           {{"centre_px", {l.crop.centre.x, l.crop.centre.y}},
            {"side_px", l.crop.side},
            {"angle_deg", l.crop.angle_deg}}}};
    }
  }
  json doc = {{"format", "handdb-query-result"},
              {"version", 1},
              {"tool_version", HANDDB_VERSION},
              {"database", flags.db_dir},
              {"image", image},
              {"input_kind", std::string(QueryInputKindName(query.kind))},
              {"query", query_json},
              {"options",
               {{"top_k", search.top_k},
                {"max_per_shape", search.max_per_shape},
                {"threads", ResolveNumThreads(search.num_threads)},
                {"brute_force", search.brute_force},
                {"hand", flags.hand.name},
                {"kdtree", flags.kdtree},
                {"dt_cell_px", search.dt_cell_px},
                {"coarse_bound", search.coarse_bound},
                {"search", std::string(SearchModeName(stats.mode))},
                {"candidates", search.index.candidates},
                {"nprobe", search.index.nprobe}}},
              {"stats",
               {{"virtual_views", stats.virtual_views},
                {"canonical_views", db.num_views()},
                {"rolls", db.num_rolls()},
                {"refined", stats.refined},
                {"abandoned", stats.abandoned},
                {"view_kdtrees", stats.view_trees},
                {"scan_abandoned", stats.probe_abandoned},
                {"grids", stats.grids},
                {"grid_bounded", stats.grid_bounded},
                {"searches", stats.searches},
                {"candidates", stats.candidates},
                {"seconds_index", stats.seconds_index},
                {"seconds", stats.seconds_total},
                {"seconds_bounds", stats.seconds_bounds},
                {"seconds_refine", stats.seconds_refine}}},
              {"matches", matches_json}};
  doc["options"]["fit"] = flags.fit == "off" ? "off" : (fit.fits.empty() ? "unavailable" : "on");
  if (fit.best >= 0) {
    json pose = MatchFitToJson(fit.fits[fit.best]);
    pose["match_rank"] = fit.best + 1;
    doc["pose"] = std::move(pose);
  }
  return doc;
}

// --export: the answer's pose as a posed glTF of the hand asset, seen through the camera that
// saw the picture. A left hand is written as the mirror image the search matched.
Status ExportPose(const QueryFlags& flags, const PictureMatches& found, const Database& db) {
  if (found.matches.empty()) {
    return Status(StatusCode::kNotFound, flags.export_glb + ": no match to export");
  }
  const DatabaseRig& rig = *flags.rig;
  PosedHandGlbOptions options;
  options.ortho_scale = rig.render.ortho_scale;
  JointVector joints{};
  if (found.fit.best >= 0) {
    const MatchFit& f = found.fit.fits[found.fit.best];
    joints = f.fit.joints;
    options.left_hand = found.matches[found.fit.best].hand == Hand::kLeft;
    // The fit's rotation is in the left hand's frame for a left hand (S_x R S_y); the export
    // wants the right hand's camera, which the same flips give back.
    options.cam_from_hand =
        options.left_hand ? MirrorCamFromHand(f.fit.cam_from_hand) : f.fit.cam_from_hand;
  } else {
    // The top match's stored view: its label (right hand, roll 0) turned by the virtual roll.
    const Match& m = found.matches.front();
    const ViewLabel label = db.label(m.view_id);
    for (int i = 0; i < kNumJointAngles; ++i) joints[i] = label.joint_angles[i];
    const Vec3d direction{
        label.view_direction[0], label.view_direction[1], label.view_direction[2]};
    auto cam = CamFromHand(rig.rig, direction, label.camera_roll + m.roll_angle);
    if (!cam.ok()) return cam.status();
    options.cam_from_hand = *cam;
    options.left_hand = m.hand == Hand::kLeft;
  }
  return WritePosedHandGlb(flags.export_glb, rig.rig, joints, options);
}

// One picture's answer: its evidence, its ranked matches and the search's counters.
struct PictureQuery {
  PictureMatches found;
  SearchStats stats;
};

// The whole work of one picture, the same in the single and the batch form: read it, search its
// edges, re-rank by its landmarks and write the contact sheet --sheet asks for. `search_threads`
// is the picture's share of --threads (a batch searches several pictures at once).
Result<PictureQuery> QueryOnePicture(const Searcher& searcher,
                                     const QueryFlags& flags,
                                     const std::string& image,
                                     int search_threads) {
  PictureSearchOptions options = flags.picture.options;
  options.search.num_threads = search_threads;
  // A picture's matches are fitted on its threads too (the same fits on any number).
  options.fit.num_threads = ResolveNumThreads(search_threads);
  PictureQuery q;
  auto found = SearchPicture(searcher, image, options, &q.stats);
  if (!found.ok()) return found.status();
  q.found = std::move(found).value();
  if (!flags.sheet.empty()) {
    const Status st = WriteSheet(
        flags, image, q.found.evidence, q.found.matches, q.found.fit, searcher.database());
    if (!st.ok()) return st;
  }
  if (!flags.export_glb.empty()) {
    const Status st = ExportPose(flags, q.found, searcher.database());
    if (!st.ok()) return st;
  }
  return q;
}

// What a batch prints for one picture: its JSON line or its headed table on stdout, or its
// error line on stderr (and, in JSON Lines, an error line on stdout so every picture has one).
struct BatchAnswer {
  std::string out;
  std::string err;
  bool failed = false;
};

BatchAnswer AnswerOnePicture(const Searcher& searcher,
                             const QueryFlags& flags,
                             const std::string& image,
                             int search_threads) {
  BatchAnswer a;
  auto q = QueryOnePicture(searcher, flags, image, search_threads);
  Status status = q.ok() ? Status() : q.status();
  if (q.ok() && flags.as_json) {
    json doc = ResultJson(flags,
                          image,
                          q->found.evidence,
                          q->found.matches,
                          q->found.fit,
                          q->stats,
                          searcher.database());
    doc["picture"] = image;
    status = ValidateJson(doc, "query_batch_line.schema.json", "query result");
    // A bug, but never print JSON that breaks the schema: the picture fails instead.
    if (status.ok()) a.out = doc.dump() + "\n";
  } else if (q.ok()) {
    a.out = "picture: " + image + "\n" +
            FormatTable(q->found.matches, q->found.evidence, q->stats, searcher.database()) +
            FormatFit(q->found.fit) + "\n";
  }
  if (!status.ok()) {
    a.failed = true;
    std::string message = status.message();
    if (message.find(image) == std::string::npos) message = image + ": " + message;
    a.err = "handdb query: " + message + "\n";
    if (flags.as_json) {
      const json line = {
          {"picture", image}, {"error", message}, {"code", StatusCodeName(status.code())}};
      a.out = line.dump() + "\n";
    }
  }
  return a;
}

// The batch form: every picture searched with the one open Searcher and landmark model, several
// at once within --threads, printed in input order as each one's turn comes. Exit 1 when any
// picture failed.
int RunBatch(const Searcher& searcher,
             QueryFlags& flags,
             const std::vector<std::string>& pictures) {
  SearchOptions& search = flags.picture.options.search;
  const auto start = search.progress_since;
  // The batch's own progress line (pictures done) replaces each search's.
  search.progress = false;
  const size_t n = pictures.size();
  // Pictures in parallel first (reading and the landmark network are one thread each), the
  // threads left over shared by each picture's search; the results do not depend on the split.
  const int threads = ResolveNumThreads(search.num_threads);
  const int workers = static_cast<int>(std::min<size_t>(static_cast<size_t>(threads), n));
  const int search_threads = std::max(1, threads / workers);
  const bool show_progress = !flags.quiet && ::isatty(STDERR_FILENO) != 0;
  Progress progress("query", n, show_progress, "pictures");
  progress.QuietUnlessSlow(start);

  std::vector<std::optional<BatchAnswer>> answers(n);
  std::mutex mu;
  size_t next = 0;
  size_t failed = 0;
  ParallelFor(n, workers, [&](size_t i, int) {
    BatchAnswer a = AnswerOnePicture(searcher, flags, pictures[i], search_threads);
    std::lock_guard<std::mutex> lock(mu);
    answers[i] = std::move(a);
    for (; next < n && answers[next]; ++next) {
      BatchAnswer& ready = *answers[next];
      if (ready.failed) {
        ++failed;
        // Clear a progress line drawn on the terminal, so the error starts its own line.
        std::fprintf(stderr, "%s%s", show_progress ? "\r\033[K" : "", ready.err.c_str());
      }
      std::fputs(ready.out.c_str(), stdout);
      std::fflush(stdout);
      answers[next] = BatchAnswer{};
    }
    progress.Add();
    return true;
  });
  progress.Finish();
  return failed > 0 ? kExitError : kExitOk;
}

}  // namespace

int RunQuery(int argc, char** argv) {
  CLI::App app{
      "Finds the database views most similar to a picture of a hand: exact top-k by the undirected "
      "chamfer distance D_c over every (view, roll), pruned with distance-transform lower bounds "
      "(docs/query.md). IMAGE is a photo (PNG/JPEG: skin-colour segmentation, or --mask), an "
      "edge image (non-zero pixels are edges) or a Blender label EXR. Several IMAGEs, a "
      "directory or - (paths on stdin) are searched as a batch: the database is opened and the "
      "landmark model loaded once, pictures run in parallel and print in input order.",
      "handdb query"};
  QueryFlags flags;
  // A long query shows progress counted from here: opening the database and loading the image
  // count towards the few seconds after which a progress line appears.
  flags.picture.options.search.progress_since = std::chrono::steady_clock::now();
  flags.Add(app);
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  if (!flags.Finish()) return flags.picture.failure_exit_code;
  const std::string& db_dir = flags.db_dir;
  std::vector<std::string> pictures = flags.images;
  if (flags.batch) {
    auto listed = ListPictures(flags.images, std::cin);
    if (!listed.ok()) return Fail("query", listed.status());
    if (listed->empty()) {
      return Fail("query",
                  Status(StatusCode::kInvalidArgument, "no pictures (the list on stdin is empty)"));
    }
    pictures = std::move(listed).value();
  }

  // With two threads or more, the landmark model loads on a thread of its own while the
  // database opens: the two are independent, and a single photo's query waits for both
  // (docs/decisions/0018). A model that cannot be loaded is still reported before the
  // database's problems. --threads 1 does one thing at a time.
  const bool overlap = ResolveNumThreads(flags.picture.options.search.num_threads) > 1;
  std::future<bool> landmarker =
      InBackground(overlap, [&flags] { return flags.picture.OpenLandmarker("query"); });
  // The pose fit and --export need the rig the database was rendered with, and the fit its
  // solver (a plugin over Ceres, pose/fit.h): both load beside the open too, on a thread of their
  // own; their errors are reported after the database's.
  const bool wants_rig = flags.fit != "off" || !flags.export_glb.empty();
  std::future<Result<DatabaseRig>> rig_loaded;
  if (wants_rig) {
    rig_loaded = InBackground(overlap, [&flags, &db_dir] {
      if (flags.fit != "off") LoadPoseFitSolver();  // once per process: its answer is read below
      return LoadDatabaseRig(db_dir);
    });
  }
  // Open the database first: a broken database is reported before any image work. Its index is
  // attached when the manifest lists one (--search auto), and searched (SearchMode::kAuto).
  SearcherOptions open;
  open.num_threads = flags.picture.options.search.num_threads;
  open.verify = flags.verify;
  open.use_index = flags.picture.options.search.brute_force
                       ? IndexUse::kExact
                       : ParseIndexUse(flags.search_mode).value();
  // One picture or a few: the stored box fields, quick to prepare. A batch of more prepares the
  // tighter centre fields once and searches each picture faster (docs/decisions/0010); the
  // answers are the same either way.
  open.few_queries = pictures.size() < kFewPictures;
  auto searcher = Searcher::Open(db_dir, open);
  if (!landmarker.get()) return flags.picture.failure_exit_code;
  if (!searcher.ok()) return Fail("query", searcher.status());
  const Database& db = (*searcher)->database();
  if (db.num_views() == 0)
    return Fail("query", Status(StatusCode::kNotFound, db_dir + ": the database has no views"));

  // What the first exact search would build before it starts (the coarse fields, the views'
  // histograms) builds on the Searcher's pool while the rig loads and the first pictures are
  // read. The same caches either way; an error is left for the search to report.
  const SearchOptions& search = flags.picture.options.search;
  std::future<void> prepared;
  if ((*searcher)->ModeFor(search) == SearchMode::kExact && !search.brute_force &&
      search.coarse_bound) {
    prepared = InBackground(overlap, [&searcher] {
      try {
        (*searcher)->PrepareExactSearch();
      } catch (...) {
      }
    });
  }

  if (wants_rig) {
    auto rig = rig_loaded.get();
    if (rig.ok()) {
      flags.rig = std::make_shared<const DatabaseRig>(std::move(rig).value());
      if (flags.fit != "off") flags.picture.options.rig = flags.rig;
      // A picture without landmarks is fitted to its silhouette only when asked for: that fit
      // does not yet improve on its match (docs/decisions/0016).
      flags.picture.options.fit.use_silhouette = flags.fit == "on";
    } else if (flags.fit == "on" || !flags.export_glb.empty()) {
      return Fail("query", rig.status());
    }
    // --fit auto on a database without its rig: the stored views alone, as --json's
    // options.fit "unavailable" says.
  }
  if (flags.picture.options.rig != nullptr) {
    if (const Status solver = LoadPoseFitSolver(); !solver.ok()) return Fail("query", solver);
  }
  // A label EXR is converted with the edge options the database was made with.
  const Status recorded = flags.picture.UseDatabaseConversion(db, db_dir);
  if (!recorded.ok()) return Fail("query", recorded);
  if (flags.batch) return RunBatch(**searcher, flags, pictures);

  const std::string& image = pictures.front();
  auto result = QueryOnePicture(**searcher, flags, image, flags.picture.options.search.num_threads);
  if (!result.ok()) return Fail("query", result.status());
  const PictureEvidence& query = result->found.evidence;
  const std::vector<Match>& matches = result->found.matches;

  if (flags.as_json) {
    const json doc = ResultJson(flags, image, query, matches, result->found.fit, result->stats, db);
    const Status valid = ValidateJson(doc, "query_result.schema.json", "query result");
    // A bug, but never print JSON that breaks the schema.
    if (!valid.ok()) return Fail("query", valid);
    std::printf("%s\n", doc.dump(2).c_str());
  } else {
    std::fputs(FormatTable(matches, query, result->stats, db).c_str(), stdout);
    std::fputs(FormatFit(result->found.fit).c_str(), stdout);
    if (!flags.sheet.empty()) std::printf("\ncontact sheet: %s\n", flags.sheet.c_str());
    if (!flags.export_glb.empty()) std::printf("pose exported: %s\n", flags.export_glb.c_str());
  }
  return kExitOk;
}

}  // namespace handdb::cli
