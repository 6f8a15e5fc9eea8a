// Query benchmark: on a paper-size database (26 shapes x 86 directions = 2,236
// canonical views x 48 rolls = 107,328 virtual views, ~600 points per view) measures, in one run,
// the median latency of a top-10 query with N threads for
//   (a) the pruned exact search (handdb's Searcher),
//   (b) brute force (exact D_c for every (view, roll), same code without pruning),
//   (c) a straightforward baseline: for every (view, roll), rotate the view, build a PCL kd-tree
//       over it and compute both directed terms with kd-trees (measured on a fraction of the
//       views and scaled up, said so in the output),
//   (d) the floor: reading every point byte of the database once from memory,
// with ratios, and the peak memory (getrusage) against the database's size on disk.
//
// With --db (a real database), it then measures what users send in four query
// sets, searched round-robin query by query so load changes hit them alike: real photos (--photos,
// searched recursively), the photo-like and the clean label renders of a test set (--testset,
// made by `handdb testset`), and the perturbed views above.
// Photos and renders become query points through `handdb query`'s own path (LoadQueryEdges, label
// EXRs with the edge options the manifest records). Per set and hand setting (`handdb query`'s
// default --hand either, and right only): median, p90 and max search latency (wall), the median
// CPU time, each median also over the perturbed views' median, the share of
// searched (view, roll) pairs refined, view kd-trees built; and brute force on the first
// --brute-queries queries of each set, which must give identical results (else exit 1, naming the
// query).
//
//   query_bench [--db DIR] [--shapes 26] [--directions 86] [--rolls 48] [--points 600]
//               [--queries 9] [--brute-queries 3] [--baseline-fraction 0.05] [--threads 2]
//               [--kdtree nanoflann|pcl] [--dt-cell 1] [--keep]
//               [--photos DIR] [--testset DIR] [--set-queries 20]
// Without --db a synthetic database (query/search_testing.h) is written to a temp directory by a
// child process (so its memory does not count) and removed afterwards unless --keep; the query
// sets need a real database and are skipped.
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "bench/bench_args.h"
#include "bench/query_sets.h"
#include "edges/view_conversion.h"
#include "evaluate/evaluate.h"
#include "evaluate/photos.h"
#include "format/manifest.h"
#include "format/shard_writer.h"
#include "photo/image_edges.h"
#include "query/search_testing.h"
#include "query/searcher.h"

namespace handdb {
namespace {

using bench::Median;
using bench::Percentile;
using bench::QuerySet;

struct Args {
  std::string db;
  uint32_t shapes = 26;
  uint32_t directions = 86;
  uint32_t rolls = 48;
  size_t points = 600;
  int queries = 9;
  int brute_queries = 3;
  double baseline_fraction = 0.05;
  int threads = 2;
  KdTreeBackend kdtree = KdTreeBackend::kNanoflann;
  float dt_cell = 1.0f;
  bool keep = false;
  // Query sets (with --db only). An empty path skips the set with a printed note.
  std::string photos = bench::DefaultPhotoDir();
  std::string testset;
  int set_queries = 20;  // per set, spread evenly over the set (0: all)
};

// CPU seconds of the whole process (all threads): on a shared machine wall time includes waiting
// for a core, CPU time does not.
double CpuSeconds() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

long PeakRssKb() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss;
}

long CurrentRssKb() {
  FILE* f = std::fopen("/proc/self/statm", "r");
  long pages = 0, resident = 0;
  if (f != nullptr) {
    if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
    std::fclose(f);
  }
  return resident * (sysconf(_SC_PAGESIZE) / 1024);
}

// Resident memory by kind, from /proc/self/smaps: the database's mapped shard files, other files
// (program and library code, read-only data) and anonymous memory (heap, stacks).
struct MemoryBreakdown {
  long db_kb = 0;
  long code_kb = 0;
  long anon_kb = 0;
};

MemoryBreakdown ReadMemoryBreakdown() {
  MemoryBreakdown m;
  FILE* f = std::fopen("/proc/self/smaps", "r");
  if (f == nullptr) return m;
  char line[4096];
  enum { kDb, kCode, kAnon } kind = kAnon;
  while (std::fgets(line, sizeof(line), f) != nullptr) {
    unsigned long lo = 0, hi = 0;
    char path[4096] = "";
    // A mapping's header line ("lo-hi perms offset dev inode [path]"); field lines ("Rss: ...")
    // never parse as two hex numbers joined by '-'.
    if (std::sscanf(line, "%lx-%lx %*s %*s %*s %*s %4095s", &lo, &hi, path) >= 2) {
      const std::string p = path;
      if (p.size() > 4 && p.compare(p.size() - 4, 4, ".hdb") == 0) {
        kind = kDb;
      } else if (!p.empty() && p[0] == '/') {
        kind = kCode;
      } else {
        kind = kAnon;
      }
      continue;
    }
    long kb = 0;
    if (std::sscanf(line, "Rss: %ld kB", &kb) == 1) {
      (kind == kDb ? m.db_kb : kind == kCode ? m.code_kb : m.anon_kb) += kb;
    }
  }
  std::fclose(f);
  return m;
}

std::string FormatBreakdown(const MemoryBreakdown& m) {
  char buf[160];
  std::snprintf(buf,
                sizeof(buf),
                "db files %.2f MB, code %.2f MB, anonymous %.2f MB",
                m.db_kb / 1024.0,
                m.code_kb / 1024.0,
                m.anon_kb / 1024.0);
  return buf;
}

Status WriteSyntheticDatabase(const std::filesystem::path& dir, const Args& args) {
  Manifest manifest;
  manifest.tool_version = "query_bench";
  manifest.rolls = args.rolls;
  nlohmann::json shapes = nlohmann::json::array();
  for (uint32_t s = 0; s < args.shapes; ++s) {
    char name[32];
    std::snprintf(name, sizeof(name), "synthetic-%02u", s);
    shapes.push_back({{"id", s}, {"name", name}});
  }
  manifest.metadata["shapes"] = shapes;
  manifest.metadata["generator"] = "query/search_testing.h SyntheticHandEdges";
  for (uint32_t s = 0; s < args.shapes; ++s) {
    char file[32];
    std::snprintf(file, sizeof(file), "shard-%05u.hdb", s);
    ShardWriter writer;
    ShardWriterOptions options;
    options.metadata_json = nlohmann::json{{"shapes", shapes}}.dump();
    HANDDB_RETURN_IF_ERROR(writer.Open(dir / file, options));
    for (uint32_t d = 0; d < args.directions; ++d) {
      const uint32_t v = s * args.directions + d;
      ViewLabel label = testing::SyntheticViewLabel(v, args.directions);
      const auto pts = testing::SyntheticHandEdges(s, d, args.directions, args.points);
      HANDDB_RETURN_IF_ERROR(writer.AddView(label, pts));
    }
    Result<ShardSummary> summary = writer.Finish();
    if (!summary.ok()) return summary.status();
    manifest.AddShard(*summary);
  }
  return WriteManifest(dir, manifest);
}

// (c): per (view, roll) a PCL kd-tree over the rolled view (float px) and both directed terms.
// Returns the seconds for the views with index % stride == 0.
double NaiveBaseline(const Database& db,
                     std::span<const Point2f> query,
                     int threads,
                     int stride,
                     double* best_distance) {
  pcl::PointCloud<pcl::PointXY>::Ptr qcloud(new pcl::PointCloud<pcl::PointXY>);
  for (const auto& p : query) {
    pcl::PointXY x;
    x.x = p.x;
    x.y = p.y;
    qcloud->push_back(x);
  }
  pcl::KdTreeFLANN<pcl::PointXY> qtree;
  const double t0 = bench::NowSeconds();
  qtree.setInputCloud(qcloud);
  std::atomic<size_t> next{0};
  std::vector<double> best(threads, 1e300);
  auto work = [&](int t) {
    std::vector<int> idx(1);
    std::vector<float> sq(1);
    std::vector<Point2f> rolled;
    for (size_t v; (v = next.fetch_add(1) * stride) < db.num_views();) {
      for (roll_id_t r = 0; r < db.num_rolls(); ++r) {
        RollPoints(db.points(static_cast<view_id_t>(v)), RollAngle(r, db.num_rolls()), &rolled);
        pcl::PointCloud<pcl::PointXY>::Ptr vcloud(new pcl::PointCloud<pcl::PointXY>);
        for (const auto& p : rolled) {
          pcl::PointXY x;
          x.x = p.x;
          x.y = p.y;
          vcloud->push_back(x);
        }
        pcl::KdTreeFLANN<pcl::PointXY> vtree;
        vtree.setInputCloud(vcloud);
        double a = 0, b = 0;
        for (const auto& p : *qcloud) {
          vtree.nearestKSearch(p, 1, idx, sq);
          a += std::sqrt(sq[0]);
        }
        for (const auto& p : *vcloud) {
          qtree.nearestKSearch(p, 1, idx, sq);
          b += std::sqrt(sq[0]);
        }
        best[t] = std::min(best[t], a / qcloud->size() + b / vcloud->size());
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work, t);
  work(0);
  for (auto& t : pool) t.join();
  *best_distance = *std::min_element(best.begin(), best.end());
  return bench::NowSeconds() - t0;
}

// (d): read every point byte once (threads split the views).
double ReadFloor(const Database& db, int threads) {
  std::atomic<uint64_t> sink{0};
  const double t0 = bench::NowSeconds();
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t) {
    pool.emplace_back([&, t] {
      uint64_t acc = 0;
      for (size_t v = t; v < db.num_views(); v += threads) {
        for (const PointQ& p : db.points(static_cast<view_id_t>(v))) {
          acc += static_cast<uint16_t>(p.x) ^ static_cast<uint16_t>(p.y);
        }
      }
      sink += acc;
    });
  }
  for (auto& t : pool) t.join();
  const double dt = bench::NowSeconds() - t0;
  if (sink.load() == 42) std::printf(" ");  // keep the reads
  return dt;
}

bool SameResults(const std::vector<Match>& a, const std::vector<Match>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].view_id != b[i].view_id || a[i].roll != b[i].roll || a[i].distance != b[i].distance) {
      return false;
    }
  }
  return true;
}

// ---- Query sets: what users send ----

namespace fs = std::filesystem;

// Nearest-rank percentile, p in (0, 1].
// The merged top-k of two searches, in the order Searcher::Search documents for Hand::kEither:
// (D_c, view id, roll, right before left).
std::vector<Match> MergeHands(std::vector<Match> right, const std::vector<Match>& left, int k) {
  for (const Match& m : left) right.push_back(m);
  std::stable_sort(right.begin(), right.end(), [](const Match& x, const Match& y) {
    if (x.distance != y.distance) return x.distance < y.distance;
    if (x.view_id != y.view_id) return x.view_id < y.view_id;
    if (x.roll != y.roll) return x.roll < y.roll;
    return x.hand == Hand::kRight && y.hand == Hand::kLeft;
  });
  if (right.size() > static_cast<size_t>(k)) right.resize(static_cast<size_t>(k));
  return right;
}

struct HandRun {
  std::vector<double> ms;             // wall time of Searcher::Search
  std::vector<double> cpu_ms;         // process CPU time of it (all threads; load-independent)
  std::vector<double> refined_share;  // refined / (searches x virtual views)
  std::vector<double> trees;          // view kd-trees built
  std::vector<std::vector<Match>> results;
};

struct SetMeasurement {
  HandRun either, right;
  int brute_checked = 0;
  std::vector<double> brute_ms;         // per brute-force search of one hand
  std::vector<std::string> mismatches;  // one line per query whose pruned result differs
};

Status SearchInto(const Searcher& searcher,
                  std::span<const Point2f> query,
                  const SearchOptions& options,
                  HandRun* run) {
  SearchStats stats;
  const double c0 = CpuSeconds();
  const double t0 = bench::NowSeconds();
  auto res = searcher.Search(query, options, &stats);
  const double ms = (bench::NowSeconds() - t0) * 1e3;
  const double cpu_ms = (CpuSeconds() - c0) * 1e3;
  if (!res.ok()) return res.status();
  run->ms.push_back(ms);
  run->cpu_ms.push_back(cpu_ms);
  run->refined_share.push_back(
      static_cast<double>(stats.refined) /
      static_cast<double>(std::max<uint64_t>(1, stats.searches * stats.virtual_views)));
  run->trees.push_back(static_cast<double>(stats.view_trees));
  run->results.push_back(std::move(res).value());
  return Status::Ok();
}

// "" when equal, else where they first differ.
std::string DescribeDifference(const std::vector<Match>& pruned, const std::vector<Match>& brute) {
  for (size_t i = 0; i < std::max(pruned.size(), brute.size()); ++i) {
    if (i >= pruned.size() || i >= brute.size()) {
      return std::to_string(pruned.size()) + " pruned matches vs " + std::to_string(brute.size()) +
             " by brute force";
    }
    const Match& p = pruned[i];
    const Match& b = brute[i];
    if (p.view_id != b.view_id || p.roll != b.roll || p.distance != b.distance ||
        p.hand != b.hand) {
      char buf[256];
      std::snprintf(buf,
                    sizeof(buf),
                    "rank %zu: pruned view %u roll %u %s D_c %.17g, brute force view %u roll %u %s "
                    "D_c %.17g",
                    i + 1,
                    p.view_id,
                    static_cast<unsigned>(p.roll),
                    std::string(HandName(p.hand)).c_str(),
                    p.distance,
                    b.view_id,
                    static_cast<unsigned>(b.roll),
                    std::string(HandName(b.hand)).c_str(),
                    b.distance);
      return buf;
    }
  }
  return "";
}

// Query i of a set with --hand either and then --hand right, so load changes hit both alike.
Status SearchBothHands(const Searcher& searcher,
                       std::span<const Point2f> query,
                       const SearchOptions& options,
                       SetMeasurement* m) {
  SearchOptions either = options, right = options;
  either.hand = Hand::kEither;
  right.hand = Hand::kRight;
  HANDDB_RETURN_IF_ERROR(SearchInto(searcher, query, either, &m->either));
  return SearchInto(searcher, query, right, &m->right);
}

// Brute force on the first `brute_queries` of a set already searched: one brute-force search per
// hand, the right one checking --hand right and both merged checking --hand either. `right_brute`
// holds brute-force right-hand results already computed for the first queries ((b) of the
// perturbed views).
Status CheckAgainstBruteForce(const Searcher& searcher,
                              const QuerySet& set,
                              const SearchOptions& options,
                              int brute_queries,
                              const std::vector<std::vector<Match>>& right_brute,
                              SetMeasurement* measurement) {
  SetMeasurement& m = *measurement;
  SearchOptions right = options;
  right.hand = Hand::kRight;
  for (size_t i = 0; i < std::min(set.points.size(), static_cast<size_t>(brute_queries)); ++i) {
    SearchOptions brute = right;
    brute.brute_force = true;
    std::vector<Match> brute_right;
    if (i < right_brute.size()) {
      brute_right = right_brute[i];
    } else {
      const double t0 = bench::NowSeconds();
      auto res = searcher.Search(set.points[i], brute);
      m.brute_ms.push_back((bench::NowSeconds() - t0) * 1e3);
      if (!res.ok()) return res.status();
      brute_right = std::move(res).value();
    }
    brute.hand = Hand::kLeft;
    const double t0 = bench::NowSeconds();
    auto brute_left = searcher.Search(set.points[i], brute);
    m.brute_ms.push_back((bench::NowSeconds() - t0) * 1e3);
    if (!brute_left.ok()) return brute_left.status();
    const std::vector<Match> brute_either = MergeHands(brute_right, *brute_left, options.top_k);
    ++m.brute_checked;
    auto check = [&](const char* hand,
                     const std::vector<Match>& pruned,
                     const std::vector<Match>& reference) {
      const std::string diff = DescribeDifference(pruned, reference);
      if (!diff.empty()) {
        m.mismatches.push_back(set.key + " query " + set.names[i] + " (--hand " + hand +
                               "): pruned search differs from brute force: " + diff);
      }
    };
    check("either", m.either.results[i], brute_either);
    check("right", m.right.results[i], brute_right);
  }
  return Status::Ok();
}

// The perturbed views' medians, the reference of every set's ratios.
struct Reference {
  double wall = std::nan("");
  double cpu = std::nan("");
};

void PrintHandRun(const std::string& key,
                  const char* hand,
                  const HandRun& run,
                  const Reference& perturbed) {
  const double median = Median(run.ms);
  std::printf(
      "  %-14s %-6s median %8.1f ms  p90 %8.1f ms  max %8.1f ms  %6.2fx perturbed  refined "
      "median %6.2f%% max %6.2f%%  view kd-trees median %.0f max %.0f  CPU median %.1f ms "
      "(%.2fx perturbed)\n",
      key.c_str(),
      hand,
      median,
      Percentile(run.ms, 0.9),
      *std::max_element(run.ms.begin(), run.ms.end()),
      median / perturbed.wall,
      100 * Median(run.refined_share),
      100 * *std::max_element(run.refined_share.begin(), run.refined_share.end()),
      Median(run.trees),
      *std::max_element(run.trees.begin(), run.trees.end()),
      Median(run.cpu_ms),
      Median(run.cpu_ms) / perturbed.cpu);
}

// The four query sets; returns the exit code (1 when a pruned result differs from brute force or
// a search or the test set fails).
int RunQuerySets(const Args& args,
                 const Searcher& searcher,
                 const SearchOptions& options,
                 QuerySet perturbed,
                 const std::vector<std::vector<Match>>& perturbed_right_brute) {
  // Exactly `handdb query`'s input options: the defaults, and for label EXRs the edge options the
  // manifest records.
  ImageEdgeOptions image_options;
  auto recorded = ReadDatabaseViewConversion(args.db);
  if (!recorded.ok()) {
    std::fprintf(stderr, "query_bench: %s\n", recorded.status().ToString().c_str());
    return 1;
  }
  image_options.label_edges = recorded->edges;
  image_options.label_joint_pairs = recorded->joint_pairs;
  auto images = bench::ImageQuerySets(args.photos, args.testset, args.set_queries, image_options);
  if (!images.ok()) {
    std::fprintf(stderr, "query_bench: %s\n", images.status().ToString().c_str());
    return 1;
  }
  std::vector<QuerySet> sets = std::move(images).value();
  sets.push_back(std::move(perturbed));

  // Round-robin over the sets, query i of every set before query i + 1 of any, so a change of the
  // machine's load hits every set alike and the ratios to the perturbed views stay meaningful on
  // a shared machine. Brute force afterwards.
  std::vector<std::optional<SetMeasurement>> measured(sets.size());
  size_t longest = 0;
  for (size_t s = 0; s < sets.size(); ++s) {
    if (!sets[s].skipped.empty() || sets[s].points.empty()) continue;
    measured[s].emplace();
    longest = std::max(longest, sets[s].points.size());
  }
  for (size_t i = 0; i < longest; ++i) {
    for (size_t s = 0; s < sets.size(); ++s) {
      if (!measured[s] || i >= sets[s].points.size()) continue;
      const Status st = SearchBothHands(searcher, sets[s].points[i], options, &*measured[s]);
      if (!st.ok()) {
        std::fprintf(stderr,
                     "query_bench: %s query %s: %s\n",
                     sets[s].key.c_str(),
                     sets[s].names[i].c_str(),
                     st.ToString().c_str());
        return 1;
      }
    }
  }
  for (size_t s = 0; s < sets.size(); ++s) {
    if (!measured[s]) continue;
    static const std::vector<std::vector<Match>> kNone;
    const bool is_perturbed = s + 1 == sets.size();
    const Status st = CheckAgainstBruteForce(searcher,
                                             sets[s],
                                             options,
                                             args.brute_queries,
                                             is_perturbed ? perturbed_right_brute : kNone,
                                             &*measured[s]);
    if (!st.ok()) {
      std::fprintf(stderr, "query_bench: %s: %s\n", sets[s].key.c_str(), st.ToString().c_str());
      return 1;
    }
  }

  double load[3] = {0, 0, 0};
  if (getloadavg(load, 3) < 1) load[0] = -1;
  std::printf(
      "\nquery sets: `handdb query`'s search (top-%d, --hand either, kd-tree %s, DT "
      "cell %.2f px) and --hand right, %d threads; latency = wall time of the search (not the "
      "input step; the sets are searched round-robin, query by query); CPU = process CPU time of "
      "the search, all threads; refined = SearchStats::refined over the (view, roll) pairs "
      "searched (2 x %llu "
      "with either; a pair scored while seeding the threshold and again later counts twice); "
      "machine load average %.1f\n",
      options.top_k,
      std::string(KdTreeBackendName(options.kdtree)).c_str(),
      options.dt_cell_px,
      args.threads,
      static_cast<unsigned long long>(searcher.database().num_virtual_views()),
      load[0]);
  Reference ref_either, ref_right;
  if (measured.back()) {
    ref_either = {Median(measured.back()->either.ms), Median(measured.back()->either.cpu_ms)};
    ref_right = {Median(measured.back()->right.ms), Median(measured.back()->right.cpu_ms)};
  }
  int rc = 0;
  for (size_t s = 0; s < sets.size(); ++s) {
    const QuerySet& set = sets[s];
    if (!set.skipped.empty()) {
      std::printf("  %-14s skipped: %s\n", set.key.c_str(), set.skipped.c_str());
      continue;
    }
    size_t points = 0;
    for (const auto& q : set.points) points += q.size();
    std::printf("  %-14s %s; %zu without a usable query; ~%zu query points",
                set.key.c_str(),
                set.description.c_str(),
                set.failed.size(),
                set.points.empty() ? 0 : points / set.points.size());
    if (!set.input_ms.empty()) std::printf("; input step median %.1f ms", Median(set.input_ms));
    std::printf("\n");
    for (const std::string& f : set.failed) std::printf("  %-14s   no query: %s\n", "", f.c_str());
    if (!measured[s]) continue;
    const SetMeasurement& m = *measured[s];
    PrintHandRun(set.key, "either", m.either, ref_either);
    PrintHandRun(set.key, "right", m.right, ref_right);
    if (m.brute_checked == 0) {
      std::printf("  %-14s brute force not run (--brute-queries 0)\n", set.key.c_str());
    } else {
      std::printf(
          "  %-14s brute force on the first %d of %zu queries (either and right; median %.0f ms "
          "per hand): %s\n",
          set.key.c_str(),
          m.brute_checked,
          set.points.size(),
          Median(m.brute_ms),
          m.mismatches.empty() ? "identical" : "DIFFERENT (see stderr)");
    }
    for (const std::string& line : m.mismatches) {
      std::fprintf(stderr, "query_bench: %s\n", line.c_str());
      rc = 1;
    }
  }
  return rc;
}

int Run(const Args& args) {
  std::filesystem::path dir = args.db;
  bool made = false;
  if (dir.empty()) {
    char tmpl[] = "/tmp/handdb-query-bench-XXXXXX";
    if (mkdtemp(tmpl) == nullptr) {
      std::fprintf(stderr, "query_bench: mkdtemp failed\n");
      return 1;
    }
    dir = tmpl;
    made = true;
    const double t0 = bench::NowSeconds();
    const pid_t pid = fork();
    if (pid == 0) {
      const Status st = WriteSyntheticDatabase(dir, args);
      if (!st.ok()) std::fprintf(stderr, "query_bench: %s\n", st.ToString().c_str());
      _exit(st.ok() ? 0 : 1);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) return 1;
    std::printf(
        "synthetic database written to %s in %.1f s\n", dir.c_str(), bench::NowSeconds() - t0);
  }

  const long rss_before = CurrentRssKb();
  const MemoryBreakdown mem_before = ReadMemoryBreakdown();
  const long peak_before = PeakRssKb();
  const double t_open = bench::NowSeconds();
  auto searcher_or = Searcher::Open(dir);
  if (!searcher_or.ok()) {
    std::fprintf(stderr, "query_bench: %s\n", searcher_or.status().ToString().c_str());
    return 1;
  }
  const Searcher& searcher = **searcher_or;
  // What the first exact search would build (the cell-major fields), counted as opening.
  searcher.PrepareExactSearch();
  const Database& db = searcher.database();
  const double open_s = bench::NowSeconds() - t_open;
  std::printf(
      "database: %zu canonical views x %u rolls = %llu virtual views, %llu points "
      "(%.0f per view), %.2f MB on disk; opened in %.1f ms\n",
      db.num_views(),
      db.num_rolls(),
      static_cast<unsigned long long>(db.num_virtual_views()),
      static_cast<unsigned long long>(db.num_points()),
      static_cast<double>(db.num_points()) / static_cast<double>(db.num_views()),
      db.size_bytes() / 1e6,
      open_s * 1e3);

  SearchOptions options;
  options.top_k = 10;
  options.num_threads = args.threads;
  options.kdtree = args.kdtree;
  options.dt_cell_px = args.dt_cell;
  std::mt19937 rng(2001);
  std::vector<double> cpu_pruned;
  std::vector<std::vector<Point2f>> queries;
  int top1_hits = 0;
  std::vector<double> t_pruned;
  std::vector<double> refined, abandoned, probed, trees, bounds_ms, refine_ms;
  std::vector<std::vector<Match>> pruned_results;
  std::vector<std::string> query_names;
  for (int i = 0; i < args.queries; ++i) {
    view_id_t v;
    roll_id_t r;
    queries.push_back(bench::PerturbedView(db, &rng, &v, &r));
    query_names.push_back(std::to_string(i) + " (near view " + std::to_string(v) + " roll " +
                          std::to_string(r) + ")");
    SearchStats stats;
    const double c0 = CpuSeconds();
    const double t0 = bench::NowSeconds();
    auto res = searcher.Search(queries.back(), options, &stats);
    t_pruned.push_back(bench::NowSeconds() - t0);
    cpu_pruned.push_back(CpuSeconds() - c0);
    if (!res.ok()) {
      std::fprintf(stderr, "query_bench: %s\n", res.status().ToString().c_str());
      return 1;
    }
    if (!res->empty() && (*res)[0].view_id == v) ++top1_hits;
    pruned_results.push_back(*res);
    refined.push_back(static_cast<double>(stats.refined));
    abandoned.push_back(static_cast<double>(stats.abandoned));
    probed.push_back(static_cast<double>(stats.probe_abandoned));
    trees.push_back(static_cast<double>(stats.view_trees));
    bounds_ms.push_back(stats.seconds_bounds * 1e3);
    refine_ms.push_back(stats.seconds_refine * 1e3);
  }
  const long peak_after_pruned = PeakRssKb();
  const MemoryBreakdown mem_after_pruned = ReadMemoryBreakdown();

  std::vector<double> t_brute, cpu_brute;
  std::vector<std::vector<Match>> brute_results;  // reused by the perturbed query set
  bool identical = true;
  SearchOptions brute = options;
  brute.brute_force = true;
  for (int i = 0; i < std::min(args.brute_queries, args.queries); ++i) {
    const double c0 = CpuSeconds();
    const double t0 = bench::NowSeconds();
    auto res = searcher.Search(queries[i], brute);
    t_brute.push_back(bench::NowSeconds() - t0);
    cpu_brute.push_back(CpuSeconds() - c0);
    identical = identical && res.ok() && SameResults(*res, pruned_results[i]);
    if (res.ok()) brute_results.push_back(*res);
  }

  const int stride = std::max(1, static_cast<int>(std::lround(1.0 / args.baseline_fraction)));
  double naive_best = 0;
  const double naive_c0 = CpuSeconds();
  const double naive_part = NaiveBaseline(db, queries[0], args.threads, stride, &naive_best);
  const double naive_fraction = static_cast<double>((db.num_views() + stride - 1) / stride) /
                                static_cast<double>(db.num_views());
  const double naive = naive_part / naive_fraction;
  const double naive_cpu = (CpuSeconds() - naive_c0) / naive_fraction;

  std::vector<double> t_floor;
  for (int i = 0; i < 5; ++i) t_floor.push_back(ReadFloor(db, args.threads));

  const double a = Median(t_pruned), b = Median(t_brute), d = Median(t_floor);
  double load[3] = {0, 0, 0};
  if (getloadavg(load, 3) < 1) load[0] = -1;
  std::printf(
      "\nquery: top-%d, %d threads, kd-tree %s, DT cell %.2f px, ~%zu query points; "
      "machine load average %.1f on %u cores\n",
      options.top_k,
      args.threads,
      std::string(KdTreeBackendName(args.kdtree)).c_str(),
      args.dt_cell,
      queries[0].size(),
      load[0],
      std::thread::hardware_concurrency());
  std::printf(
      "  (a) pruned exact     median %9.1f ms  over %d queries (bounds %.1f ms + refine %.1f ms; "
      "refined %.0f pairs, %.0f abandoned early (%.0f by the linear scans, before a kd-tree), %.0f "
      "view "
      "kd-trees)\n",
      a * 1e3,
      args.queries,
      Median(bounds_ms),
      Median(refine_ms),
      Median(refined),
      Median(abandoned),
      Median(probed),
      Median(trees));
  const bool have_brute = !t_brute.empty();
  if (have_brute) {
    std::printf(
        "  (b) brute force      median %9.1f ms  over %zu queries; results identical to (a): %s\n",
        b * 1e3,
        t_brute.size(),
        identical ? "yes" : "NO");
  } else {
    std::printf("  (b) brute force      not run (--brute-queries 0)\n");
  }
  std::printf(
      "  (c) naive PCL        %12.1f ms  (measured %.1f ms on %.1f%% of the views, scaled)\n",
      naive * 1e3,
      naive_part * 1e3,
      naive_fraction * 100);
  std::printf("  (d) read DB floor    median %9.2f ms\n", d * 1e3);
  if (have_brute) std::printf("  ratios: (b)/(a) = %.1fx   ", b / a);
  std::printf(
      "%s(c)/(a) = %.0fx   (a)/(d) = %.1fx\n", have_brute ? "" : "  ratios: ", naive / a, a / d);
  const double ac = Median(cpu_pruned), bc = Median(cpu_brute);
  std::printf(
      "  CPU time (all threads; independent of other load): (a) %.1f ms, (b) %.1f ms, "
      "(c) %.1f ms; (a) CPU / %d threads = %.1f ms; (b)/(a) = %.1fx, (c)/(a) = %.0fx\n",
      ac * 1e3,
      have_brute ? bc * 1e3 : 0.0,
      naive_cpu * 1e3,
      args.threads,
      ac / args.threads * 1e3,
      have_brute ? bc / ac : 0.0,
      naive_cpu / ac);
  std::printf("  top-1 is the perturbed view: %d of %d queries\n", top1_hits, args.queries);
  const double db_kb = static_cast<double>(db.size_bytes()) / 1024.0;
  std::printf(
      "memory: RSS before opening %.1f MB, peak during (a) %.1f MB (+%.1f MB), peak overall "
      "%.1f MB; DB on disk %.2f MB; (peak during (a) - RSS before) / DB = %.2f\n",
      rss_before / 1024.0,
      peak_after_pruned / 1024.0,
      (peak_after_pruned - std::max(rss_before, 0L)) / 1024.0,
      PeakRssKb() / 1024.0,
      db_kb / 1024.0,
      static_cast<double>(peak_after_pruned - rss_before) / db_kb);
  std::printf(
      "targets: (a) <= 250 ms: %s; (b)/(a) >= 20: %s; memory <= 1.5x DB: %s\n",
      a <= 0.25 ? "met" : "MISSED",
      !have_brute   ? "not measured"
      : b / a >= 20 ? "met"
                    : "MISSED",
      static_cast<double>(peak_after_pruned - rss_before) <= 1.5 * db_kb ? "met" : "MISSED");
  std::printf("  resident before opening: %s\n", FormatBreakdown(mem_before).c_str());
  std::printf("  resident after (a):       %s\n", FormatBreakdown(mem_after_pruned).c_str());
  (void)peak_before;
  int sets_rc = 0;
  if (args.db.empty()) {
    std::printf("\nquery sets: skipped, they need a real database (--db DIR)\n");
  } else {
    QuerySet perturbed;
    perturbed.key = "perturbed";
    perturbed.description =
        "the " + std::to_string(queries.size()) + " perturbed database views of (a) (--queries)";
    perturbed.names = query_names;
    perturbed.points = queries;
    if (brute_results.size() != t_brute.size()) brute_results.clear();
    sets_rc = RunQuerySets(args, searcher, options, std::move(perturbed), brute_results);
  }
  if (made && !args.keep) std::filesystem::remove_all(dir);
  return identical && sets_rc == 0 ? 0 : 1;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  handdb::Args args;
  CLI::App app(
      "Query benchmark: pruned exact search against brute force, a PCL baseline and the "
      "read floor; with --db also the query sets (see the top of query_bench.cc).",
      "query_bench");
  handdb::bench::AddQuerySetFlags(app, args);
  app.add_option("--shapes", args.shapes, "synthetic database: shapes")->capture_default_str();
  app.add_option("--directions", args.directions, "synthetic database: view directions")
      ->capture_default_str();
  app.add_option("--rolls", args.rolls, "synthetic database: rolls")->capture_default_str();
  app.add_option("--points", args.points, "synthetic database: points per view")
      ->capture_default_str();
  app.add_option("--queries", args.queries, "perturbed views timed")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--brute-queries", args.brute_queries, "queries also searched by brute force")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--baseline-fraction", args.baseline_fraction, "views the PCL baseline times")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  std::string kdtree = "nanoflann";
  app.add_option("--kdtree", kdtree, "view kd-tree backend")
      ->check(CLI::IsMember({"nanoflann", "pcl"}))
      ->capture_default_str();
  app.add_option("--dt-cell", args.dt_cell, "distance transform cell, px")->capture_default_str();
  app.add_flag("--keep", args.keep, "keep the synthetic database");
  if (int rc = handdb::bench::ParseBenchArgs(app, argc, argv); rc >= 0) return rc;
  args.kdtree = *handdb::ParseKdTreeBackend(kdtree);
  if (args.baseline_fraction <= 0) {
    std::fprintf(stderr, "query_bench: --baseline-fraction must be > 0\n");
    return 2;
  }
  return handdb::Run(args);
}
