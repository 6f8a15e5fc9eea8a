// The pose fit measured against a test set's truth, one JSON line per test view: the truth's
// keypoints, the landmark network's joints (2D, depths, world joints) in the query's normalised
// frame, and for each of the first --matches matches of the search `handdb evaluate` runs, the
// match's keypoints and its fit's (keypoints with depth, each cost part, iterations). Each
// --variant refits the same matches with other fit options, so one search serves every variant.
// What is chosen from the lines (the answer among N fits, the 3D error in the plane and in depth)
// is left to the reader of the lines (docs/decisions/0019-depth-from-the-landmark-network.md).
//
//   fit_study --db DB --testset TS --out lines.jsonl [--matches 10] [--landmark-passes 2]
//             [--variant name:key=v,...]
//
// Keys: joint_sigma, rotation_sigma, landmark_sigma, tolerance, depth_weight, depth_sigma,
// depth_loss_scale, depth_from_wrist, min_presence, and for the silhouette term beside the
// landmarks silhouette (1: on), silhouette_sigma, inside_weight, edge_weight, cover_weight.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_args.h"
#include "evaluate/evaluate.h"
#include "generator/hand/database_rig.h"
#include "photo/hand_landmarks.h"
#include "photo/image_edges.h"
#include "pose/fit_matches.h"
#include "pose/landmark_rank.h"
#include "query/searcher.h"

namespace handdb {
namespace {

using json = nlohmann::json;

struct Args {
  std::string db;
  std::string testset;
  std::string out;
  int matches = 10;
  int threads = 1;
  int limit = 0;
  int landmark_passes = PictureOptions{}.landmark_passes;
  std::vector<std::string> variants;
};

json Points3(const std::array<std::array<float, 3>, kNumKeypoints>& p) {
  json out = json::array();
  for (const auto& q : p) out.push_back({q[0], q[1], q[2]});
  return out;
}

// "name:key=value,key=value" over the fit options a study varies.
Result<std::pair<std::string, MatchFitOptions>> ParseVariant(const std::string& text) {
  MatchFitOptions options;
  options.max_matches = 0;
  const size_t colon = text.find(':');
  const std::string name = text.substr(0, colon);
  if (colon == std::string::npos) return std::make_pair(name, options);
  std::stringstream rest(text.substr(colon + 1));
  std::string item;
  while (std::getline(rest, item, ',')) {
    const size_t eq = item.find('=');
    if (eq == std::string::npos) {
      return Status(StatusCode::kInvalidArgument, "variant " + text + ": " + item + " has no =");
    }
    const std::string key = item.substr(0, eq);
    const double v = std::stod(item.substr(eq + 1));
    PoseFitOptions& f = options.fit;
    if (key == "joint_sigma") {
      f.joint_prior_sigma = v;
    } else if (key == "rotation_sigma") {
      f.rotation_prior_sigma = v;
    } else if (key == "landmark_sigma") {
      f.landmark_sigma_px = v;
    } else if (key == "tolerance") {
      f.function_tolerance = v;
    } else if (key == "depth_weight") {
      f.depth_weight = v;
    } else if (key == "depth_sigma") {
      f.depth_sigma = v;
    } else if (key == "depth_loss_scale") {
      f.depth_loss_scale = v;
    } else if (key == "depth_from_wrist") {
      f.depth_from_wrist = v != 0;
    } else if (key == "silhouette") {
      options.silhouette_with_landmarks = v != 0;
    } else if (key == "silhouette_sigma") {
      f.silhouette_sigma_px = v;
    } else if (key == "inside_weight") {
      f.inside_weight = v;
    } else if (key == "edge_weight") {
      f.edge_weight = v;
    } else if (key == "cover_weight") {
      f.cover_weight = v;
    } else if (key == "min_presence") {
      options.min_presence = static_cast<float>(v);
    } else {
      return Status(StatusCode::kInvalidArgument, "variant " + text + ": unknown key " + key);
    }
  }
  return std::make_pair(name, options);
}

int Run(const Args& args) {
  std::vector<std::pair<std::string, MatchFitOptions>> variants;
  variants.emplace_back("default", MatchFitOptions{});
  for (const std::string& v : args.variants) {
    auto parsed = ParseVariant(v);
    if (!parsed.ok()) {
      std::fprintf(stderr, "fit_study: %s\n", parsed.status().ToString().c_str());
      return 2;
    }
    variants.push_back(*parsed);
  }
  for (auto& [name, options] : variants) {
    options.max_matches = args.matches;
    options.use_silhouette = true;  // as `handdb evaluate --fit on`
  }
  auto testset = ReadTestSet(args.testset);
  auto rig = LoadDatabaseRig(args.db);
  auto landmarker = HandLandmarker::Open(HandLandmarker::DefaultModelPath());
  SearcherOptions open;
  open.num_threads = args.threads;
  auto searcher = Searcher::Open(args.db, open);
  for (const Status& s : {testset.status(), rig.status(), landmarker.status(), searcher.status()}) {
    if (!s.ok()) {
      std::fprintf(stderr, "fit_study: %s\n", s.ToString().c_str());
      return 1;
    }
  }
  std::ofstream out(args.out);
  SearchOptions search;
  search.top_k = 100;  // evaluate's first_k: the landmark re-ranking's pool follows it
  search.num_threads = args.threads;
  const LandmarkRankOptions rank;
  PictureOptions picture_options;
  picture_options.edges.kind = QueryInputKind::kPhoto;
  picture_options.landmark_passes = args.landmark_passes;
  picture_options.landmarker = *landmarker;
  int done = 0;
  for (const TestView& view : testset->views) {
    if (args.limit > 0 && done >= args.limit) break;
    ++done;
    json line = {{"id", view.id}, {"truth", Points3(view.truth.keypoints)}};
    auto picture = ReadPicture(view.photo, picture_options);
    if (!picture.ok()) {
      line["error"] = picture.status().message();
      out << line.dump() << "\n";
      continue;
    }
    const QueryEdges& q = picture->edges;
    if (picture->landmarks.has_value()) {
      const HandLandmarks& l = *picture->landmarks;
      json lm = json::array(), depth = json::array(), world = json::array();
      for (int k = 0; k < kNumLandmarks; ++k) {
        lm.push_back(
            {(l.image_px[k].x - q.centre_x) * q.scale, (l.image_px[k].y - q.centre_y) * q.scale});
        depth.push_back(l.depth_px[k] * q.scale);
        world.push_back({l.world_m[k][0], l.world_m[k][1], l.world_m[k][2]});
      }
      line["presence"] = l.presence;
      line["landmarks"] = lm;
      line["depth"] = depth;
      if (l.has_world) line["world"] = world;
    }
    auto matches = SearchEvidence(**searcher, *picture, search, rank);
    if (!matches.ok()) {
      line["error"] = matches.status().message();
      out << line.dump() << "\n";
      continue;
    }
    json ms = json::array();
    for (size_t i = 0; i < std::min<size_t>(10, matches->size()); ++i) {
      ms.push_back({{"keypoints", Points3((*matches)[i].label.keypoints)},
                    {"left", (*matches)[i].hand == Hand::kLeft}});
    }
    line["matches"] = ms;
    for (const auto& [name, options] : variants) {
      const auto t0 = std::chrono::steady_clock::now();
      auto fit = FitPictureMatches(*rig, (*searcher)->database(), *picture, *matches, options);
      const double ms =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      if (!fit.ok()) {
        std::fprintf(stderr, "fit_study: %s\n", fit.status().ToString().c_str());
        return 1;
      }
      json fits = json::array();
      for (const MatchFit& mf : fit->fits) {
        if (!mf.fitted) {
          fits.push_back({{"fitted", false}, {"reason", mf.reason}});
          continue;
        }
        json k3 = json::array();
        for (const auto& p : mf.keypoints_3d) k3.push_back({p[0], p[1], p[2]});
        fits.push_back({{"fitted", true},
                        {"keypoints", k3},
                        {"final", mf.fit.final_cost},
                        {"landmark", mf.fit.landmark_cost},
                        {"prior", mf.fit.prior_cost},
                        {"silhouette", mf.fit.silhouette_cost},
                        {"depth", mf.fit.depth_cost},
                        {"iterations", mf.fit.iterations},
                        {"landmark_px", mf.landmark_error_px}});
      }
      line["fits"][name] = {{"best", fit->best},
                            {"landmarks", fit->landmarks_used},
                            {"silhouette", fit->silhouette_used},
                            {"ms", ms},
                            {"fits", fits}};
    }
    out << line.dump() << "\n";
    std::fprintf(stderr, "\rfit_study %d / %zu", done, testset->views.size());
  }
  std::fprintf(stderr, "\n");
  return 0;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  handdb::Args args;
  CLI::App app("The pose fit against a test set's truth: one JSON line per test view");
  app.add_option("--db", args.db, "database directory")->required();
  app.add_option("--testset", args.testset, "test set made by `handdb testset`")->required();
  app.add_option("--out", args.out, "JSON lines written here")->required();
  app.add_option("--matches", args.matches, "matches fitted per view")->capture_default_str();
  app.add_option("--threads", args.threads, "search threads")->capture_default_str();
  app.add_option("--limit", args.limit, "the first N views only (0: all)");
  app.add_option("--landmark-passes",
                 args.landmark_passes,
                 "runs of the landmark network a view (as `handdb query --landmark-passes`)")
      ->check(CLI::Range(1, 2))
      ->capture_default_str();
  app.add_option("--variant",
                 args.variants,
                 "name:key=value,... fit options refitted (keys: the file's first comment)");
  const int parsed = handdb::bench::ParseBenchArgs(app, argc, argv);
  if (parsed >= 0) return parsed;
  return handdb::Run(args);
}
