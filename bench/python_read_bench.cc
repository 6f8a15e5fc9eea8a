// The C++ side of bench/python_bench.py: the same reads and searches the Python
// benchmark makes, timed in C++, so the script can print Python / C++ ratios from one run.
//
//   python_read_bench scan DB [--reps 20]
//       open every shard of the manifest + ShardReader::ScanViews, every point and label touched
//       (docs/format.md's sequential scan, over a whole database); per rep: wall and CPU seconds
//   python_read_bench query DB [--reps 5] [--threads 2] [--top 10] [--hand either]
//                      [--view V --roll R]... [--image PATH]...
//       Searcher::Search on each query (a stored view rolled, or an image through
//       LoadQueryEdges outside the timing); per rep and query: wall seconds of the call and the
//       search's own stats.seconds_total
// Prints one JSON document on stdout.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "edges/view_conversion.h"
#include "format/manifest.h"
#include "format/roll.h"
#include "format/shard_reader.h"
#include "photo/image_edges.h"
#include "query/database.h"
#include "query/searcher.h"

namespace handdb {
namespace {

using json = nlohmann::json;

[[noreturn]] void Die(const std::string& message) {
  std::fprintf(stderr, "python_read_bench: %s\n", message.c_str());
  std::exit(1);
}

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double ProcessCpu() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

json Scan(const std::string& db_dir, int reps) {
  json wall = json::array(), cpu = json::array();
  int64_t checksum = 0;
  uint64_t views = 0, points = 0;
  for (int rep = 0; rep < reps; ++rep) {
    const double w0 = Now(), c0 = ProcessCpu();
    auto manifest = ReadManifest(db_dir);
    if (!manifest.ok()) Die(manifest.status().message());
    int64_t acc = 0;
    views = points = 0;
    for (const auto& s : manifest->shards) {
      auto reader = ShardReader::Open(std::filesystem::path(db_dir) / s.file);
      if (!reader.ok()) Die(reader.status().message());
      const Status st =
          reader->ScanViews([&](size_t, const ViewLabel& l, std::span<const PointQ> pts) {
            int64_t sx = 0, sy = 0;
            for (const PointQ& p : pts) {
              sx += p.x;
              sy += p.y;
            }
            acc += sx + sy + static_cast<int64_t>(l.joint_angles[0] * 1000) + l.render_id;
            ++views;
            points += pts.size();
            return Status::Ok();
          });
      if (!st.ok()) Die(st.message());
    }
    wall.push_back(Now() - w0);
    cpu.push_back(ProcessCpu() - c0);
    checksum = acc;
  }
  return {
      {"wall", wall}, {"cpu", cpu}, {"views", views}, {"points", points}, {"checksum", checksum}};
}

json Query(const std::string& db_dir,
           int reps,
           const SearchOptions& options,
           const std::vector<std::pair<int, int>>& view_queries,
           const std::vector<std::string>& images) {
  auto db = Database::Open(db_dir);
  if (!db.ok()) Die(db.status().message());
  auto shared = std::make_shared<const Database>(std::move(db).value());
  const Searcher searcher(shared);
  std::vector<std::vector<Point2f>> queries;
  std::vector<std::string> names;
  for (const auto& [v, r] : view_queries) {
    std::vector<Point2f> pts;
    RollPoints(shared->points(static_cast<view_id_t>(v)),
               RollAngle(static_cast<roll_id_t>(r), shared->num_rolls()),
               &pts);
    queries.push_back(std::move(pts));
    names.push_back("view " + std::to_string(v) + " roll " + std::to_string(r));
  }
  auto recorded = ReadDatabaseViewConversion(db_dir);
  if (!recorded.ok()) Die(recorded.status().message());
  for (const std::string& image : images) {
    ImageEdgeOptions edge_options;
    edge_options.label_edges = recorded->edges;
    edge_options.label_joint_pairs = recorded->joint_pairs;
    auto edges = LoadQueryEdges(image, edge_options);
    if (!edges.ok()) Die(edges.status().message());
    queries.push_back(edges->points_px());
    names.push_back(image);
  }
  json out = json::array();
  for (size_t q = 0; q < queries.size(); ++q) {
    json wall = json::array(), inner = json::array();
    json top;
    for (int rep = 0; rep < reps; ++rep) {
      SearchStats stats;
      const double t0 = Now();
      auto matches = searcher.Search(queries[q], options, &stats);
      wall.push_back(Now() - t0);
      if (!matches.ok()) Die(matches.status().message());
      inner.push_back(stats.seconds_total);
      if (!matches->empty()) {
        top = {{"view_id", matches->front().view_id},
               {"roll", matches->front().roll},
               {"distance", matches->front().distance}};
      }
    }
    out.push_back({{"query", names[q]}, {"wall", wall}, {"search_seconds", inner}, {"top", top}});
  }
  return out;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  using namespace handdb;
  if (argc < 3) Die("usage: python_read_bench scan|query DB [options] (see the source)");
  const std::string mode = argv[1], db = argv[2];
  int reps = mode == "scan" ? 20 : 5;
  SearchOptions options;
  options.num_threads = 2;
  options.hand = Hand::kEither;
  std::vector<std::pair<int, int>> views;
  std::vector<std::string> images;
  int pending_view = -1;
  for (int i = 3; i + 1 < argc; i += 2) {
    const std::string flag = argv[i], value = argv[i + 1];
    if (flag == "--reps") {
      reps = std::atoi(value.c_str());
    } else if (flag == "--threads") {
      options.num_threads = std::atoi(value.c_str());
    } else if (flag == "--top") {
      options.top_k = std::atoi(value.c_str());
    } else if (flag == "--hand") {
      auto h = ParseHand(value);
      if (!h.ok()) Die(h.status().message());
      options.hand = *h;
    } else if (flag == "--view") {
      pending_view = std::atoi(value.c_str());
    } else if (flag == "--roll") {
      if (pending_view < 0) Die("--roll needs a --view before it");
      views.emplace_back(pending_view, std::atoi(value.c_str()));
      pending_view = -1;
    } else if (flag == "--image") {
      images.push_back(value);
    } else {
      Die("unknown flag " + flag);
    }
  }
  if (!options.Check()) Die("bad search options");
  const json out = mode == "scan"    ? Scan(db, reps)
                   : mode == "query" ? Query(db, reps, options, views, images)
                                     : json();
  if (out.is_null()) Die("mode must be scan or query");
  std::printf("%s\n", out.dump().c_str());
  return 0;
}
