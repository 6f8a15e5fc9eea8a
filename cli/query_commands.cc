// `handdb query DB IMAGE`: the top-k database views for a picture of a hand.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/json_schema.h"
#include "base/thread_pool.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/photo_input_flags.h"
#include "format/roll.h"
#include "generator/hand/database_rig.h"
#include "handdb_version.h"
#include "photo/image_edges.h"
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

void PrintTable(const std::vector<Match>& matches,
                const PictureEvidence& picture,
                const SearchStats& st,
                const Database& db) {
  const QueryEdges& q = picture.edges;
  std::printf(
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
    std::printf("hand landmarks: presence %.3f, %s\n",
                static_cast<double>(picture.landmarks->presence),
                used ? "the nearest views re-ranked by D_c / best D_c + weight x landmark error "
                       "(column lm, in hand radii)"
                     : "below the 0.9 the ranking needs: ranked by D_c alone");
  }
  std::printf(
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
    std::printf(
        "indexed search: %llu candidate pairs from the index (%.1f ms), the top %s exact "
        "among them (--search exact: every pair)\n\n",
        static_cast<unsigned long long>(st.candidates),
        st.seconds_index * 1e3,
        "k");
  }
  // Key joint angles: the flexion of each finger's base joint (thumb CMC, index..pinky MCP).
  std::printf("%4s  %8s  %5s  %-16s  %-5s  %7s %7s  %6s  %29s\n",
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
    std::printf(
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
}

// The fitted pose under the table: from which match, how far the keypoints moved towards the
// landmarks, and the solver's verdict.
void PrintFit(const PictureFit& fit) {
  if (fit.fits.empty()) return;
  if (fit.best < 0) {
    std::printf("\npose fit: none (%s)\n", fit.fits.front().reason.c_str());
    return;
  }
  const MatchFit& f = fit.fits[fit.best];
  std::printf(
      "\nfitted pose (from match %d of %zu fitted): landmark error %.2f -> %.2f px (normalised), "
      "%s after %d iterations\n",
      fit.best + 1,
      fit.fits.size(),
      f.landmark_error_start_px,
      f.landmark_error_px,
      f.fit.termination.c_str(),
      f.fit.iterations);
  std::printf("  joints (deg):");
  for (double a : f.fit.joints) std::printf(" %.0f", a * kDeg);
  std::printf("\n");
}

// The flags of `handdb query`, bound to the option structs they set.
struct QueryFlags {
  std::string db_dir, image, sheet;
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
  app.add_option("IMAGE", image, "query image: photo, edge image or label EXR")->required();
  app.add_option("--top", search.top_k, "number of matches")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_option("--per-shape",
                 search.max_per_shape,
                 "at most this many matches per basic shape (0: no limit); 1 ranks shapes: "
                 "the --top nearest shapes, each by its best view")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  app.add_flag("--json", as_json, "print the result as JSON (schemas/query_result.schema.json)");
  app.add_option("--sheet", sheet, "write a contact sheet PNG: input, its edges, the top matches");
  app.add_option("--threads", search.num_threads, "worker threads (-1: all cores)")
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
                 "grid; auto: when the database carries its rig (hand_model.json); off: the "
                 "stored views alone")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->capture_default_str();
  app.add_option("--fit-matches",
                 picture.options.fit.max_matches,
                 "fit this many of the first matches; the best fit by its cost is the pose")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_flag("--quiet,-q",
               quiet,
               "no progress line (otherwise one on stderr once a search runs 1 s on a "
               "terminal, 5 s otherwise)");
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
  if (!picture.Finish("query")) return false;
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
  search.hand = hand.Get();
  if (!search.Check()) {
    std::fprintf(stderr, "handdb query: invalid search options (see above)\n");
    return false;
  }
  return true;
}

// The contact sheet of --sheet: the input, its edges and each match's edges at its roll.
Status WriteSheet(const QueryFlags& flags,
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
  return WriteContactSheet(
      flags.sheet, flags.image, picture, tiles, ContactSheetOptions{}, skeleton);
}

// The --json document (schemas/query_result.schema.json).
json ResultJson(const QueryFlags& flags,
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
          {"presence", l.presence},
          {"used", UsesLandmarks(picture, flags.picture.options.landmark_rank)},
          {"weight", flags.picture.options.landmark_rank.weight},
          {"image_px", px},
          {"crop",
           {{"centre_px", {l.crop_centre.x, l.crop_centre.y}},
            {"side_px", l.crop_side_px},
            {"angle_deg", l.crop_angle_deg}}}};
    }
  }
  json doc = {{"format", "handdb-query-result"},
              {"version", 1},
              {"tool_version", HANDDB_VERSION},
              {"database", flags.db_dir},
              {"image", flags.image},
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

}  // namespace

int RunQuery(int argc, char** argv) {
  CLI::App app{
      "Finds the database views most similar to a picture of a hand: exact top-k by the undirected "
      "chamfer distance D_c over every (view, roll), pruned with distance-transform lower bounds "
      "(docs/query.md). IMAGE is a photo (PNG/JPEG: skin-colour segmentation, or --mask), an "
      "edge image (non-zero pixels are edges) or a Blender label EXR.",
      "handdb query"};
  QueryFlags flags;
  // A long query shows progress counted from here: opening the database and loading the image
  // count towards the few seconds after which a progress line appears.
  flags.picture.options.search.progress_since = std::chrono::steady_clock::now();
  flags.Add(app);
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  if (!flags.Finish()) return flags.picture.failure_exit_code;
  const std::string& db_dir = flags.db_dir;

  // Open the database first: a broken database is reported before any image work. Its index is
  // attached when the manifest lists one (--search auto), and searched (SearchMode::kAuto).
  SearcherOptions open;
  open.num_threads = flags.picture.options.search.num_threads;
  open.verify = flags.verify;
  open.use_index = flags.picture.options.search.brute_force
                       ? IndexUse::kExact
                       : ParseIndexUse(flags.search_mode).value();
  open.few_queries = true;
  auto searcher = Searcher::Open(db_dir, open);
  if (!searcher.ok()) return Fail("query", searcher.status());
  const Database& db = (*searcher)->database();
  if (db.num_views() == 0)
    return Fail("query", Status(StatusCode::kNotFound, db_dir + ": the database has no views"));

  // The pose fit needs the rig the database was rendered with.
  if (flags.fit != "off") {
    auto rig = LoadDatabaseRig(db_dir);
    if (rig.ok()) {
      flags.picture.options.rig = std::make_shared<const DatabaseRig>(std::move(rig).value());
    } else if (flags.fit == "on") {
      return Fail("query", rig.status());
    } else if (!flags.quiet) {
      std::fprintf(stderr, "handdb query: no pose fit: %s\n", rig.status().message().c_str());
    }
  }
  // A label EXR is converted with the edge options the database was made with.
  const Status recorded = flags.picture.UseDatabaseConversion(db, db_dir);
  if (!recorded.ok()) return Fail("query", recorded);
  SearchStats stats;
  auto result = SearchPicture(**searcher, flags.image, flags.picture.options, &stats);
  if (!result.ok()) return Fail("query", result.status());
  const PictureEvidence& query = result->evidence;
  const std::vector<Match>& matches = result->matches;

  if (!flags.sheet.empty()) {
    const Status st = WriteSheet(flags, query, matches, result->fit, db);
    if (!st.ok()) return Fail("query", st);
  }

  if (flags.as_json) {
    const json doc = ResultJson(flags, query, matches, result->fit, stats, db);
    const Status valid = ValidateJson(doc, "query_result.schema.json", "query result");
    // A bug, but never print JSON that breaks the schema.
    if (!valid.ok()) return Fail("query", valid);
    std::printf("%s\n", doc.dump(2).c_str());
  } else {
    PrintTable(matches, query, stats, db);
    PrintFit(result->fit);
    if (!flags.sheet.empty()) std::printf("\ncontact sheet: %s\n", flags.sheet.c_str());
  }
  return kExitOk;
}

}  // namespace handdb::cli
