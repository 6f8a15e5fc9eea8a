// Indexed search benchmark (docs/index.md): on a database with an index (`handdb
// index`), per query set (real photos, a test set's photo-like and clean label renders, perturbed
// views; bench/query_sets.h) and for each --candidates count, the latency (median, p90, max; wall
// and CPU of the whole process) of indexed search with `handdb query`'s defaults (top 10, --hand
// either), its recall@1 and recall@10 against exact search of the same queries, the candidates
// and the pairs refined; and exact search's latency in the same run (queries interleaved, so
// load changes hit both alike). Exact results can be cached (--cache FILE, the format of
// bench/index_study.cc) because exact search of a 10M-view database takes seconds per query.
//
//   index_bench --db DIR [--photos DIR] [--testset DIR] [--set-queries 20] [--perturbed 10]
//               [--threads 2] [--candidates 2000,8000] [--nprobe 0] [--cache FILE]
//               [--exact-queries N]   exact latency measured on the first N queries per set
//                                     (default all; their results always come from the cache
//                                     when it has them)
#include <sys/resource.h>

#include <cinttypes>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>

#include "bench/bench_args.h"
#include "bench/query_sets.h"

namespace handdb {
namespace {

using bench::Median;
using bench::NowSeconds;
using bench::Percentile;
using bench::QuerySet;

struct Args {
  std::string db, testset, cache;
  std::string photos = bench::DefaultPhotoDir();
  int set_queries = 20;
  int perturbed = 10;
  int threads = 2;
  std::vector<int> candidates = {2000, 8000};
  int nprobe = 0;
  int exact_queries = -1;
};

double CpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

long PeakRssKb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss;
}

// The exact-result cache: one line per query, "set<TAB>name<TAB>points<TAB>seconds v r h d ...".
std::map<std::string, std::vector<Match>> ReadCache(const std::string& file) {
  std::map<std::string, std::vector<Match>> out;
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string set, name, npts;
    std::getline(ss, set, '\t');
    std::getline(ss, name, '\t');
    std::getline(ss, npts, '\t');
    double seconds = 0;
    ss >> seconds;
    std::vector<Match> top;
    uint32_t v = 0, roll = 0;
    int h = 0;
    double d = 0;
    while (ss >> v >> roll >> h >> d) {
      Match m;
      m.view_id = v;
      m.roll = roll;
      m.hand = h ? Hand::kLeft : Hand::kRight;
      m.distance = d;
      top.push_back(m);
    }
    out[set + "\t" + name + "\t" + npts] = top;
  }
  return out;
}

void AppendCache(const std::string& file,
                 const std::string& key,
                 double seconds,
                 const std::vector<Match>& top) {
  if (file.empty()) return;
  std::ofstream out(file, std::ios::app);
  out << key << "\t" << seconds;
  char buf[64];
  for (const Match& m : top) {
    std::snprintf(buf, sizeof(buf), "%.17g", m.distance);
    out << " " << m.view_id << " " << m.roll << " " << (m.hand == Hand::kLeft ? 1 : 0) << " "
        << buf;
  }
  out << "\n";
}

int Run(const Args& args) {
  const double t_open = NowSeconds();
  auto searcher_or = Searcher::Open(args.db);
  if (!searcher_or.ok()) {
    std::fprintf(stderr, "index_bench: %s\n", searcher_or.status().ToString().c_str());
    return 1;
  }
  Searcher& searcher = **searcher_or;
  const Database& db = searcher.database();
  auto index = ViewIndex::Open(args.db, db.manifest());
  if (!index.ok()) {
    std::fprintf(stderr, "index_bench: %s\n", index.status().ToString().c_str());
    return 1;
  }
  const uint64_t index_bytes = db.manifest().index->bytes;
  searcher.SetIndex(std::make_shared<const ViewIndex>(std::move(index).value()));
  const double open_s = NowSeconds() - t_open;
  const ViewIndex& ix = *searcher.index();
  std::printf(
      "database %s: %zu canonical views x %u rolls = %" PRIu64
      " virtual views; shards %.1f MB (%.1f bytes per virtual view), index %.1f MB (%.2f "
      "bytes per virtual view: %d dims, %d lists, %dx%d cells of %d px); opened in %.2f s\n",
      args.db.c_str(),
      db.num_views(),
      db.num_rolls(),
      db.num_virtual_views(),
      static_cast<double>(db.size_bytes()) / 1e6,
      static_cast<double>(db.size_bytes()) / static_cast<double>(db.num_virtual_views()),
      static_cast<double>(index_bytes) / 1e6,
      static_cast<double>(index_bytes) / static_cast<double>(db.num_virtual_views()),
      ix.dims(),
      ix.nlist(),
      ix.grid().side,
      ix.grid().side,
      ix.grid().cell_units / 16,
      open_s);

  auto input = bench::QueryInputOptions(db);
  if (!input.ok()) {
    std::fprintf(stderr, "index_bench: %s\n", input.status().ToString().c_str());
    return 1;
  }
  auto images = bench::ImageQuerySets(args.photos, args.testset, args.set_queries, *input);
  if (!images.ok()) {
    std::fprintf(stderr, "index_bench: %s\n", images.status().ToString().c_str());
    return 1;
  }
  std::vector<QuerySet> sets = std::move(images).value();
  sets.push_back(bench::PerturbedQuerySet(db, args.perturbed, 12345));

  auto cache = ReadCache(args.cache);
  SearchOptions exact;
  exact.hand = Hand::kEither;
  exact.num_threads = args.threads;
  exact.top_k = 10;
  std::printf(
      "top-10, --hand either, %d threads, nprobe %d of %d lists%s; recall@k: share of the "
      "exact top-k (view, roll, hand) in the indexed top-k, mean over queries\n",
      args.threads,
      args.nprobe > 0 ? std::min(args.nprobe, ix.nlist()) : ix.nlist(),
      ix.nlist(),
      args.nprobe > 0 ? "" : " (every view, one batched scan)");
  const long rss_before = PeakRssKb();
  for (const QuerySet& set : sets) {
    if (!set.skipped.empty()) {
      std::printf("\n%s: skipped (%s)\n", set.key.c_str(), set.skipped.c_str());
      continue;
    }
    std::printf("\n%s: %s\n", set.key.c_str(), set.description.c_str());
    std::vector<std::vector<Match>> want(set.points.size());
    std::vector<double> exact_ms, exact_cpu;
    const size_t ncand = args.candidates.size();
    std::vector<std::vector<double>> ms(ncand), cpu(ncand), r1(ncand), r10(ncand), refined(ncand),
        cands(ncand), filter_ms(ncand);
    for (size_t i = 0; i < set.points.size(); ++i) {
      const std::string key =
          set.key + "\t" + set.names[i] + "\t" + std::to_string(set.points[i].size());
      const bool time_exact = args.exact_queries < 0 || static_cast<int>(i) < args.exact_queries;
      auto hit = cache.find(key);
      if (hit == cache.end() || time_exact) {
        // What the first exact search builds (the cell-major fields), outside the timed query;
        // a run whose exact results all come from the cache never builds it, so its memory is
        // an indexed-only process's.
        searcher.PrepareExactSearch();
        const double c0 = CpuSeconds(), t0 = NowSeconds();
        auto res = searcher.Search(set.points[i], exact);
        const double t = NowSeconds() - t0;
        if (!res.ok()) {
          std::fprintf(stderr, "index_bench: %s\n", res.status().ToString().c_str());
          return 1;
        }
        exact_ms.push_back(1e3 * t);
        exact_cpu.push_back(1e3 * (CpuSeconds() - c0));
        want[i] = *res;
        if (hit == cache.end()) AppendCache(args.cache, key, t, want[i]);
      } else {
        want[i] = hit->second;
      }
      for (size_t c = 0; c < ncand; ++c) {
        SearchOptions o = exact;
        o.mode = SearchMode::kIndexed;
        o.index.candidates = args.candidates[c];
        o.index.nprobe = args.nprobe;
        SearchStats stats;
        const double c0 = CpuSeconds(), t0 = NowSeconds();
        auto res = searcher.Search(set.points[i], o, &stats);
        ms[c].push_back(1e3 * (NowSeconds() - t0));
        cpu[c].push_back(1e3 * (CpuSeconds() - c0));
        if (!res.ok()) {
          std::fprintf(stderr, "index_bench: %s\n", res.status().ToString().c_str());
          return 1;
        }
        r1[c].push_back(bench::RecallAt(*res, want[i], 1));
        r10[c].push_back(bench::RecallAt(*res, want[i], 10));
        refined[c].push_back(static_cast<double>(stats.refined));
        cands[c].push_back(static_cast<double>(stats.candidates));
        filter_ms[c].push_back(1e3 * stats.seconds_index);
      }
    }
    if (!exact_ms.empty()) {
      std::printf(
          "  exact            median %8.1f ms  p90 %8.1f  max %8.1f  (CPU median %.1f ms, "
          "%zu queries)\n",
          Median(exact_ms),
          Percentile(exact_ms, 0.9),
          *std::max_element(exact_ms.begin(), exact_ms.end()),
          Median(exact_cpu),
          exact_ms.size());
    }
    for (size_t c = 0; c < ncand; ++c) {
      auto mean = [](const std::vector<double>& v) {
        double s = 0;
        for (double x : v) s += x;
        return v.empty() ? 0.0 : s / static_cast<double>(v.size());
      };
      std::printf(
          "  indexed C=%-6d median %8.1f ms  p90 %8.1f  max %8.1f  (CPU median %.1f ms; "
          "filter median %.1f ms)  candidates %.0f  refined median %.0f  recall@1 %.3f  "
          "recall@10 %.3f (worst query %.1f)\n",
          args.candidates[c],
          Median(ms[c]),
          Percentile(ms[c], 0.9),
          *std::max_element(ms[c].begin(), ms[c].end()),
          Median(cpu[c]),
          Median(filter_ms[c]),
          Median(cands[c]),
          Median(refined[c]),
          mean(r1[c]),
          mean(r10[c]),
          *std::min_element(r10[c].begin(), r10[c].end()));
    }
    std::fflush(stdout);
  }
  std::printf(
      "\nmemory: peak RSS %.1f MB (%.1f MB before the queries); shards + index on disk "
      "%.1f MB; decoded views held %.1f MB (coded shards)\n",
      static_cast<double>(PeakRssKb()) / 1024,
      static_cast<double>(rss_before) / 1024,
      static_cast<double>(db.size_bytes() + index_bytes) / 1048576.0,
      static_cast<double>(db.decoded_bytes()) / 1048576.0);
  return 0;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  handdb::Args args;
  CLI::App app("Indexed search against exact search, per query set (docs/index.md).",
               "index_bench");
  handdb::bench::AddQuerySetFlags(app, args);
  app.add_option("--cache", args.cache, "exact results cache (read, then extended)");
  app.add_option("--perturbed", args.perturbed, "perturbed database views")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  handdb::bench::AddList(app, "--candidates", args.candidates, "candidate counts, N,M");
  app.add_option("--nprobe", args.nprobe, "IVF lists probed (0: the index's default)")
      ->capture_default_str();
  app.add_option("--exact-queries",
                 args.exact_queries,
                 "exact latency measured on the first N queries per set (default all; their "
                 "results always come from the cache when it has them)");
  if (int rc = handdb::bench::ParseBenchArgs(app, argc, argv); rc >= 0) return rc;
  if (args.db.empty()) {
    std::fprintf(stderr, "index_bench: --db DIR is required\n");
    return 2;
  }
  return handdb::Run(args);
}
