// The start of a `handdb` process and one photo through it, in fresh processes, each against a
// baseline measured in the same run, so a busy machine moves both alike:
//   (a) start-up: `handdb --help` and `handdb version` against a process that does nothing
//       (/bin/true, the floor of any start here), with the shared objects the binary loads
//       (LD_TRACE_LOADED_OBJECTS, as ldd) and the dynamic loader's relocations
//       (LD_DEBUG=statistics);
//   (b) one photo: `handdb query DB PHOTO --top 10 --json` (landmarks and fit as by default, and
//       with --fit off) against the search it runs, timed in this process on its own: a warm
//       SearchEvidence of the photo (the re-ranking's pool when it has landmarks), the open and
//       the model load beside it;
//   (c) with --baseline BINARY (another handdb build), every process measurement alternates
//       between the two binaries run by run and prints this one's median over the baseline's.
// Medians of --runs runs; wall and CPU (user + system) of each process, and its page faults.
//
//   startup_bench [--handdb PATH] [--baseline PATH] [--db DIR --photo FILE] [--runs 21]
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_args.h"
#include "bench/median.h"
#include "bench/query_sets.h"
#include "bench/run_process.h"
#include "photo/hand_landmarks.h"
#include "photo/image_edges.h"
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
  std::string handdb = HANDDB_BINARY;
  std::string baseline;
  std::string db;
  std::string photo;
  int runs = 21;
  int threads = 2;
};

struct Series {
  std::vector<double> wall_ms, cpu_ms, faults;
  int failed = 0;
  void Add(const Timed& t) {
    wall_ms.push_back(t.seconds * 1e3);
    cpu_ms.push_back(t.cpu_seconds * 1e3);
    faults.push_back(static_cast<double>(t.minor_faults));
    failed += t.ok ? 0 : 1;
  }
};

// The same command of this binary and, with a baseline, of the baseline alternately.
struct Pair {
  Series now, base;
};

Pair Measure(const Args& args, const std::vector<std::string>& tail, int runs) {
  Pair p;
  for (int r = 0; r < runs; ++r) {
    std::vector<std::string> argv = {args.handdb};
    argv.insert(argv.end(), tail.begin(), tail.end());
    p.now.Add(RunTimed(argv, ""));
    if (!args.baseline.empty()) {
      argv[0] = args.baseline;
      p.base.Add(RunTimed(argv, ""));
    }
  }
  return p;
}

void PrintRow(const char* name, const Series& s, double reference_ms, const char* reference) {
  std::printf("  %-28s wall %7.1f ms  CPU %7.1f ms  %6.0f faults  %5.2fx %s%s\n",
              name,
              Median(s.wall_ms),
              Median(s.cpu_ms),
              Median(s.faults),
              Median(s.wall_ms) / reference_ms,
              reference,
              s.failed > 0 ? "  (some runs FAILED)" : "");
}

void PrintPair(const char* name, const Pair& p, double reference_ms, const char* reference) {
  PrintRow(name, p.now, reference_ms, reference);
  if (p.base.wall_ms.empty()) return;
  PrintRow("  baseline", p.base, reference_ms, reference);
  std::printf("  %-28s wall %6.2fx  CPU %6.2fx of the baseline\n",
              "  this / baseline",
              Median(p.now.wall_ms) / Median(p.base.wall_ms),
              Median(p.now.cpu_ms) / Median(p.base.cpu_ms));
}

std::string ReadText(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The shared objects `binary` loads before main, as ldd lists them (the vDSO included).
int LoadedObjects(const std::string& binary, const fs::path& tmp) {
  const fs::path out = tmp / "objects.txt";
  RunTimed({binary, "--help"}, out.string(), "", {"LD_TRACE_LOADED_OBJECTS=1"});
  std::istringstream lines(ReadText(out));
  int n = 0;
  for (std::string line; std::getline(lines, line);) n += line.empty() ? 0 : 1;
  return n;
}

// The dynamic loader's symbol and relative relocations at start (LD_DEBUG=statistics).
std::string Relocations(const std::string& binary, const fs::path& tmp) {
  const fs::path out = tmp / "ld-statistics";
  RunTimed({binary, "--help"}, "", "", {"LD_DEBUG=statistics", "LD_DEBUG_OUTPUT=" + out.string()});
  std::string text;
  for (const auto& entry : fs::directory_iterator(tmp)) {
    if (entry.path().filename().string().rfind("ld-statistics", 0) == 0) {
      text += ReadText(entry.path());
      fs::remove(entry.path());
    }
  }
  std::smatch m;
  std::string symbols = "?", relative = "?";
  if (std::regex_search(text, m, std::regex(R"(final number of relocations: (\d+))"))) {
    symbols = m[1];
  }
  if (std::regex_search(text, m, std::regex(R"(number of relative relocations: (\d+))"))) {
    relative = m[1];
  }
  return symbols + " symbol + " + relative + " relative";
}

int Run(const Args& args) {
  const fs::path tmp = fs::temp_directory_path() / ("startup_bench-" + std::to_string(getpid()));
  fs::create_directories(tmp);
  std::printf("startup_bench: %s%s%s, %d runs each, medians\n\n",
              args.handdb.c_str(),
              args.baseline.empty() ? "" : " against ",
              args.baseline.c_str(),
              args.runs);

  // (a) Start-up against a process that does nothing.
  Series floor;
  for (int r = 0; r < args.runs; ++r) floor.Add(RunTimed({"/bin/true"}, ""));
  const double floor_ms = Median(floor.wall_ms);
  std::printf("start-up (ratio: to the floor, /bin/true):\n");
  PrintRow("/bin/true (the floor)", floor, floor_ms, "the floor");
  const Pair help = Measure(args, {"--help"}, args.runs);
  PrintPair("handdb --help", help, floor_ms, "the floor");
  const Pair version = Measure(args, {"version"}, args.runs);
  PrintPair("handdb version", version, floor_ms, "the floor");
  std::printf("  shared objects loaded: %d, relocations: %s\n",
              LoadedObjects(args.handdb, tmp),
              Relocations(args.handdb, tmp).c_str());
  if (!args.baseline.empty()) {
    std::printf("  baseline: %d shared objects, relocations: %s\n",
                LoadedObjects(args.baseline, tmp),
                Relocations(args.baseline, tmp).c_str());
  }
  std::printf("\n");

  if (!args.db.empty() && !args.photo.empty()) {
    // (b) The search the query runs, in this process: open, model, then warm searches.
    SearcherOptions open_options;
    open_options.num_threads = args.threads;
    open_options.few_queries = true;  // as `handdb query` opens it for one picture
    double t0 = NowSeconds();
    auto searcher = Searcher::Open(args.db, open_options);
    const double open_ms = (NowSeconds() - t0) * 1e3;
    if (!searcher.ok()) {
      std::fprintf(stderr, "startup_bench: %s\n", searcher.status().message().c_str());
      return 1;
    }
    t0 = NowSeconds();
    auto landmarker = HandLandmarker::Open(HandLandmarker::DefaultModelPath());
    const double model_ms = (NowSeconds() - t0) * 1e3;
    PictureSearchOptions options;
    if (landmarker.ok()) options.picture.landmarker = std::move(landmarker).value();
    options.landmark_rank.enabled = options.picture.landmarker != nullptr;
    options.search.hand = Hand::kEither;  // `handdb query`'s default
    options.search.num_threads = args.threads;
    auto evidence = ReadPicture(args.photo, options.picture);
    if (!evidence.ok()) {
      std::fprintf(stderr, "startup_bench: %s\n", evidence.status().message().c_str());
      return 1;
    }
    std::vector<double> search_ms;
    double first_ms = 0;
    for (int r = 0; r <= std::max(3, args.runs / 2); ++r) {
      t0 = NowSeconds();
      auto found = SearchEvidence(**searcher, *evidence, options.search, options.landmark_rank);
      const double ms = (NowSeconds() - t0) * 1e3;
      if (!found.ok()) {
        std::fprintf(stderr, "startup_bench: %s\n", found.status().message().c_str());
        return 1;
      }
      (r == 0 ? first_ms : search_ms.emplace_back()) = ms;
    }
    const double search = Median(search_ms);
    std::printf("one photo, %s (ratio: to the warm search alone, %.1f ms):\n",
                fs::path(args.photo).filename().c_str(),
                search);
    std::printf("  in this process: open %.1f ms, model load %.1f ms, first search %.1f ms\n",
                open_ms,
                model_ms,
                first_ms);
    const std::string threads = std::to_string(args.threads);
    const Pair fit =
        Measure(args,
                {"query", args.db, args.photo, "--top", "10", "--json", "--threads", threads},
                args.runs);
    PrintPair("handdb query --json", fit, search, "the search");
    const Pair off = Measure(args,
                             {"query",
                              args.db,
                              args.photo,
                              "--top",
                              "10",
                              "--json",
                              "--threads",
                              threads,
                              "--fit",
                              "off"},
                             args.runs);
    PrintPair("handdb query --fit off", off, search, "the search");
  }
  fs::remove_all(tmp);
  return 0;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  handdb::Args args;
  CLI::App app{"The start of handdb and one photo through it, against baselines in the same run"};
  app.add_option("--handdb", args.handdb, "the handdb binary")->capture_default_str();
  app.add_option("--baseline", args.baseline, "another handdb binary, run alternately");
  app.add_option("--db", args.db, "database for the one-photo query");
  app.add_option("--photo", args.photo, "the photo of the one-photo query");
  app.add_option("--runs", args.runs, "runs of each process")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  app.add_option("--threads", args.threads, "--threads of the query and of the search")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  if (int rc = handdb::bench::ParseBenchArgs(app, argc, argv); rc >= 0) return rc;
  return handdb::Run(args);
}
