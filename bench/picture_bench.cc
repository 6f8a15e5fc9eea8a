// The whole path of `handdb query` for photos, stage by stage, against the search alone: on a
// real database and the development photos, in one run,
//   (a) start-up: `handdb --help`, a process that loads the binary's libraries and exits;
//   (b) in this process, each stage of a picture timed on its own: the database open
//       (Searcher::Open as `handdb query` opens it), the landmark model load, the decode
//       (photo/image_read.h), segmentation and edges (LoadQueryEdges less its decode), the
//       landmarks (ReadPicture less LoadQueryEdges: the network's runs, two by default), the top-k
//       search of the edges, the search of the re-ranking's pool, the landmark re-ranking, the pose
//       fit (FitPictureMatches, when the database has its rig) and SearchPicture as a whole. Cold
//       is the first call in the process (the first photo: lazy caches, first network run), warm
//       the median of the rest (open and model: of --repeats more); each warm median also as a
//       ratio to the warm search of the pool, the search a photo with landmarks runs;
//   (c) `handdb query DB PHOTO` run once per photo (median wall per photo) against one
//       `handdb query DB PHOTO...` batch over the same photos and threads, and whether every
//       photo got the same matches both ways;
//   (d) the batch over every photo under --photos (`handdb query DB - --json`, the paths on
//       stdin), with the default fit and with --fit off: photos/s, and the CPU time of the
//       process over wall time x threads (how busy the threads were).
//
//   picture_bench --db DIR [--photos DIR] [--set-queries 24] [--threads 2] [--repeats 5]
//                 [--handdb PATH]
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_args.h"
#include "bench/query_sets.h"
#include "bench/run_process.h"
#include "evaluate/photos.h"
#include "generator/hand/database_rig.h"
#include "photo/hand_landmarks.h"
#include "photo/image_edges.h"
#include "photo/image_read.h"
#include "pose/fit_matches.h"
#include "pose/landmark_rank.h"
#include "pose/picture_search.h"
#include "query/searcher.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using bench::Median;
using bench::NowSeconds;
using bench::RunTimed;
using bench::Timed;

struct Args {
  std::string db;
  std::string photos = bench::DefaultPhotoDir();
  int set_queries = 24;
  int threads = 2;
  int repeats = 5;
  std::string handdb = HANDDB_BINARY;
};

// The matches (view, roll, hand, D_c) of one query result, to compare two runs' answers.
std::string MatchesKey(const nlohmann::json& result) {
  std::string key;
  for (const auto& m : result["matches"]) {
    key += std::to_string(m["view_id"].get<int>()) + "/" + std::to_string(m["roll"].get<int>()) +
           "/" + m["hand"].get<std::string>() + "/" + m["distance"].dump() + " ";
  }
  return key;
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

struct Stage {
  explicit Stage(const char* stage_name) : name(stage_name) {}
  const char* name;
  double cold_ms = 0;
  std::vector<double> warm_ms;
};

// A stage's cold and warm times and its warm median over the warm search of the pool.
void PrintStage(const Stage& s, double search_ms, const char* note = "") {
  std::printf("  %-34s %9.2f %9.2f %8.2f  %s\n",
              s.name,
              s.cold_ms,
              Median(s.warm_ms),
              Median(s.warm_ms) / search_ms,
              note);
}

int Run(const Args& args) {
  const std::string threads = std::to_string(args.threads);
  std::printf("picture_bench: database %s, photos %s, %d threads\n\n",
              args.db.c_str(),
              args.photos.c_str(),
              args.threads);

  // (a) Start-up.
  std::vector<double> start_ms;
  for (int r = 0; r < std::max(args.repeats, 1) * 4; ++r) {
    const Timed t = RunTimed({args.handdb, "--help"}, "");
    if (!t.ok) {
      std::fprintf(stderr, "picture_bench: %s --help failed\n", args.handdb.c_str());
      return 1;
    }
    start_ms.push_back(t.seconds * 1e3);
  }
  std::printf("start-up (handdb --help, %zu runs): median %.1f ms, min %.1f ms\n\n",
              start_ms.size(),
              Median(start_ms),
              *std::min_element(start_ms.begin(), start_ms.end()));

  // The photos: spread over the sorted files, as the other benches pick them.
  std::vector<fs::path> files;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(args.photos, ec);
       !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    std::error_code type_ec;
    if (it->is_regular_file(type_ec) && IsPhotoFile(it->path())) files.push_back(it->path());
  }
  std::sort(files.begin(), files.end());
  std::vector<std::string> photos;
  for (size_t i : bench::SpreadSample(files.size(), args.set_queries))
    photos.push_back(files[i].string());
  if (photos.size() < 2) {
    std::fprintf(stderr, "picture_bench: fewer than 2 photos under %s\n", args.photos.c_str());
    return 1;
  }

  // (b) The stages in this process.
  Stage open{"open (Searcher::Open)"}, model{"landmark model load"};
  SearcherOptions open_options;
  open_options.num_threads = args.threads;
  open_options.few_queries = true;  // as `handdb query` opens it
  std::unique_ptr<Searcher> searcher;
  for (int r = 0; r <= args.repeats; ++r) {
    const double t0 = NowSeconds();
    auto s = Searcher::Open(args.db, open_options);
    const double ms = (NowSeconds() - t0) * 1e3;
    if (!s.ok()) {
      std::fprintf(stderr, "picture_bench: %s\n", s.status().message().c_str());
      return 1;
    }
    (r == 0 ? open.cold_ms : open.warm_ms.emplace_back()) = ms;
    searcher = std::move(s).value();
  }
  std::shared_ptr<const HandLandmarker> landmarker;
  for (int r = 0; r <= args.repeats; ++r) {
    const double t0 = NowSeconds();
    auto m = HandLandmarker::Open(HandLandmarker::DefaultModelPath());
    const double ms = (NowSeconds() - t0) * 1e3;
    if (!m.ok()) {
      std::fprintf(stderr, "picture_bench: %s\n", m.status().message().c_str());
      return 1;
    }
    (r == 0 ? model.cold_ms : model.warm_ms.emplace_back()) = ms;
    landmarker = std::move(m).value();
  }

  // The pose fit `handdb query` runs by default, when the database carries its rig.
  std::shared_ptr<const DatabaseRig> rig;
  if (auto r = LoadDatabaseRig(args.db); r.ok()) {
    rig = std::make_shared<const DatabaseRig>(std::move(r).value());
  }

  PictureSearchOptions options;
  options.picture.landmarker = landmarker;
  options.rig = rig;
  options.search.hand = Hand::kEither;  // `handdb query`'s default
  options.search.num_threads = args.threads;
  SearchOptions pool_search = options.search;
  pool_search.top_k = std::max(options.search.top_k, options.landmark_rank.pool_views);

  Stage decode{"decode"}, segment{"segmentation + edges"}, network{"landmarks (network runs)"},
      search{"search (top 10 of the edges)"}, pool{"search (the re-ranking's pool)"},
      rerank{"re-rank by landmarks"}, fit{"pose fit (FitPictureMatches)"},
      whole{"SearchPicture (all of it)"};
  int failed = 0;
  for (size_t i = 0; i < photos.size(); ++i) {
    // Cold: the first photo with a hand (the first search, the first network run).
    const bool cold = failed == static_cast<int>(i);
    auto put = [cold](Stage& s, double ms) { (cold ? s.cold_ms : s.warm_ms.emplace_back()) = ms; };
    double t0 = NowSeconds();
    auto bgr = ReadImage(photos[i], cv::IMREAD_COLOR);
    const double decode_ms = (NowSeconds() - t0) * 1e3;
    t0 = NowSeconds();
    auto edges = LoadQueryEdges(photos[i], options.picture.edges);
    const double edges_ms = (NowSeconds() - t0) * 1e3;
    t0 = NowSeconds();
    auto evidence = ReadPicture(photos[i], options.picture);
    const double evidence_ms = (NowSeconds() - t0) * 1e3;
    if (!bgr.ok() || !edges.ok() || !evidence.ok() || !evidence->landmarks) {
      ++failed;  // no hand: not a picture the stages can be timed on
      continue;
    }
    put(decode, decode_ms);
    put(segment, edges_ms - decode_ms);
    put(network, evidence_ms - edges_ms);
    const std::vector<Point2f> points = evidence->edges.points_px();
    t0 = NowSeconds();
    auto top = searcher->Search(points, options.search);
    put(search, (NowSeconds() - t0) * 1e3);
    t0 = NowSeconds();
    auto pool_matches = searcher->Search(points, pool_search);
    put(pool, (NowSeconds() - t0) * 1e3);
    if (!top.ok() || !pool_matches.ok()) return 1;
    t0 = NowSeconds();
    const std::vector<Match> ranked = RerankByLandmarks(
        std::move(pool_matches).value(), *evidence, options.search, options.landmark_rank);
    put(rerank, (NowSeconds() - t0) * 1e3);
    if (rig != nullptr) {
      t0 = NowSeconds();
      auto fitted = FitPictureMatches(*rig, searcher->database(), *evidence, ranked, options.fit);
      put(fit, (NowSeconds() - t0) * 1e3);
      if (!fitted.ok()) return 1;
    }
    t0 = NowSeconds();
    auto all = SearchPicture(*searcher, photos[i], options);
    put(whole, (NowSeconds() - t0) * 1e3);
  }
  if (decode.warm_ms.empty()) {
    std::fprintf(stderr, "picture_bench: no photo with a hand and landmarks\n");
    return 1;
  }
  std::printf("stages in one process (%zu photos, %d without a hand or landmarks), ms:\n",
              photos.size(),
              failed);
  std::printf("  %-34s %9s %9s %8s\n", "stage", "cold", "warm", "/search");
  const double search_ms = Median(pool.warm_ms);
  PrintStage(open, search_ms, "cold: the first open in the process");
  PrintStage(model, search_ms);
  PrintStage(decode, search_ms);
  PrintStage(segment, search_ms, "LoadQueryEdges less its decode");
  PrintStage(network, search_ms);
  PrintStage(search, search_ms);
  PrintStage(pool, search_ms, "what SearchEvidence searches for a photo with landmarks");
  PrintStage(rerank, search_ms);
  if (rig != nullptr)
    PrintStage(fit, search_ms, "the first 3 matches fitted on one thread (--fit auto)");
  PrintStage(whole, search_ms);
  const double per_picture = Median(whole.warm_ms);
  const double fixed = Median(start_ms) + Median(open.warm_ms) + Median(model.warm_ms);
  std::printf(
      "  one process per photo pays start-up + open + model = %.1f ms (warm) on top of "
      "%.1f ms per photo\n\n",
      fixed,
      per_picture);

  // (c) One process per photo against one batch.
  const fs::path tmp = fs::temp_directory_path() / ("picture_bench-" + std::to_string(getpid()));
  fs::create_directories(tmp);
  std::vector<std::string> single_keys(photos.size());
  std::vector<double> per_process_s, batch_s, per_photo_s;
  bool same = true;
  for (int r = 0; r < std::max(1, args.repeats / 2); ++r) {
    double total = 0;
    for (size_t i = 0; i < photos.size(); ++i) {
      const std::string out = (tmp / ("single-" + std::to_string(i) + ".json")).string();
      const Timed t = RunTimed(
          {args.handdb, "query", args.db, photos[i], "--json", "-q", "--threads", threads}, out);
      // A photo without a hand fails in both forms; its time still counts.
      total += t.seconds;
      per_photo_s.push_back(t.seconds);
      if (t.ok && r == 0) single_keys[i] = MatchesKey(nlohmann::json::parse(ReadText(out)));
    }
    per_process_s.push_back(total);
    std::vector<std::string> argv = {args.handdb, "query", args.db};
    argv.insert(argv.end(), photos.begin(), photos.end());
    for (const char* a : {"--json", "-q", "--threads"}) argv.push_back(a);
    argv.push_back(threads);
    const std::string out = (tmp / "batch.jsonl").string();
    batch_s.push_back(RunTimed(argv, out).seconds);
    std::istringstream lines(ReadText(out));
    size_t i = 0;
    for (std::string line; std::getline(lines, line); ++i) {
      const auto doc = nlohmann::json::parse(line);
      const std::string key = doc.contains("matches") ? MatchesKey(doc) : "";
      same = same && i < photos.size() && doc["picture"] == photos[i] && key == single_keys[i];
    }
    same = same && i == photos.size();
  }
  fs::remove_all(tmp);
  const double n = static_cast<double>(photos.size());
  const double single_rate = n / Median(per_process_s);
  const double batch_rate = n / Median(batch_s);
  std::printf("%zu photos, %d threads, median of %zu runs:\n",
              photos.size(),
              args.threads,
              per_process_s.size());
  std::printf("  one process per photo   %7.2f s  %6.2f photos/s  (median %.1f ms a photo)\n",
              Median(per_process_s),
              single_rate,
              Median(per_photo_s) * 1e3);
  std::printf("  one batch process       %7.2f s  %6.2f photos/s  (%.2fx)\n",
              Median(batch_s),
              batch_rate,
              batch_rate / single_rate);
  std::printf("  same matches both ways: %s\n\n", same ? "yes" : "NO");

  // (d) The batch over every photo, the paths on stdin as a script would send them.
  const fs::path list =
      fs::temp_directory_path() / ("picture_bench-" + std::to_string(getpid()) + "-photos.txt");
  {
    std::ofstream out(list);
    for (const fs::path& f : files) out << f.string() << "\n";
  }
  std::printf(
      "batch of all %zu photos (handdb query DB - --json), %d threads, median of %d runs:\n",
      files.size(),
      args.threads,
      std::max(1, args.repeats / 2));
  for (const char* fit_mode : {"auto", "off"}) {
    std::vector<double> wall_s, cpu_s;
    for (int r = 0; r < std::max(1, args.repeats / 2); ++r) {
      const Timed t = RunTimed({args.handdb,
                                "query",
                                args.db,
                                "-",
                                "--json",
                                "-q",
                                "--threads",
                                threads,
                                "--fit",
                                fit_mode},
                               "",
                               list.string());
      wall_s.push_back(t.seconds);
      cpu_s.push_back(t.cpu_seconds);
    }
    const double wall = Median(wall_s);
    const double cpu = Median(cpu_s);
    std::printf(
        "  --fit %-4s  %7.2f s  %6.2f photos/s  CPU %6.2f s (%.1f ms a photo), threads "
        "busy %3.0f%%\n",
        fit_mode,
        wall,
        static_cast<double>(files.size()) / wall,
        cpu,
        cpu / static_cast<double>(files.size()) * 1e3,
        100.0 * cpu / (wall * args.threads));
  }
  fs::remove(list);
  return same ? 0 : 1;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  handdb::Args args;
  CLI::App app{"The photo path of handdb query stage by stage, and batch against per-process"};
  app.add_option("--db", args.db, "database directory")->required();
  app.add_option("--photos", args.photos, "real photos, searched recursively")
      ->capture_default_str();
  app.add_option("--set-queries", args.set_queries, "photos used, spread over the set")
      ->check(CLI::Range(2, 100000))
      ->capture_default_str();
  app.add_option("--threads", args.threads, "threads of the searches and of both query forms")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--repeats", args.repeats, "repeats of the open, model load and process runs")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--handdb", args.handdb, "the handdb binary")->capture_default_str();
  if (int rc = handdb::bench::ParseBenchArgs(app, argc, argv); rc >= 0) return rc;
  return handdb::Run(args);
}
