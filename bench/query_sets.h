// The query sets of the benchmarks ("measure what users send"; docs/query.md, docs/index.md): real
// photos, a test set's photo-like and clean label renders, and perturbed database views, each
// turned into query points by `handdb query`'s own input path. Shared by bench/query_bench.cc,
// bench/index_bench.cc and bench/index_study.cc; header-only (benchmarks are single files).
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "base/repo_root.h"
#include "bench/median.h"
#include "edges/view_conversion.h"
#include "evaluate/evaluate.h"
#include "evaluate/photos.h"
#include "photo/image_edges.h"
#include "query/search_testing.h"
#include "query/searcher.h"

namespace handdb::bench {

// --photos' default: the development photos beside the source tree (bench/run.sh's default too);
// HANDDB_SOURCE_DIR moves it with the tree (base/repo_root.h).
inline std::string DefaultPhotoDir() {
  return (RepoRoot() / ".." / "shared" / "photos" / "asl-digits").lexically_normal().string();
}

inline double NowSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Nearest-rank percentile, p in (0, 1].
inline double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<size_t>(std::ceil(p * static_cast<double>(v.size())));
  return v[std::clamp<size_t>(rank, 1, v.size()) - 1];
}

// At most `cap` of n items, evenly spread (item floor((2i + 1) n / 2cap)); over sorted paths this
// takes from every folder instead of the first folder's files. cap <= 0: all.
inline std::vector<size_t> SpreadSample(size_t n, int cap) {
  std::vector<size_t> picks;
  const size_t c = cap <= 0 ? n : std::min(n, static_cast<size_t>(cap));
  for (size_t i = 0; i < c; ++i) picks.push_back(c == n ? i : (2 * i + 1) * n / (2 * c));
  return picks;
}

struct QuerySet {
  std::string key;                 // photos, testset-photo, testset-clean, perturbed
  std::string description;         // what the queries are
  std::string skipped;             // not empty: the set was not measured, and why
  std::vector<std::string> names;  // per query: the file, or the perturbed view
  std::vector<std::vector<Point2f>> points;
  std::vector<std::string> failed;  // "name: error" of inputs without a usable query
  std::vector<double> input_ms;     // per image query: the picture -> points step
};

// The picture -> points step of `handdb query` (cli/query_commands.cc): LoadQueryEdges with the
// query's options, so a failure here is a failure there.
inline void AddImageQuery(const std::filesystem::path& image,
                          const std::string& name,
                          const ImageEdgeOptions& options,
                          QuerySet* set) {
  const double t0 = NowSeconds();
  auto edges = LoadQueryEdges(image, options);
  const double ms = (NowSeconds() - t0) * 1e3;
  if (!edges.ok()) {
    set->failed.push_back(name + ": " + edges.status().message());
    return;
  }
  set->names.push_back(name);
  set->points.push_back(edges->points_px());
  set->input_ms.push_back(ms);
}

// At most `cap` photos found recursively under `dir`, spread over the sorted paths.
inline QuerySet PhotoQuerySet(const std::string& dir, int cap, const ImageEdgeOptions& options) {
  namespace fs = std::filesystem;
  QuerySet set;
  set.key = "photos";
  std::error_code ec;
  if (dir.empty() || !fs::is_directory(dir, ec)) {
    set.skipped = dir.empty() ? "no --photos DIR" : dir + ": no such directory";
    return set;
  }
  std::vector<fs::path> files;
  for (auto it =
           fs::recursive_directory_iterator(dir, fs::directory_options::skip_permission_denied, ec);
       !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    std::error_code type_ec;
    if (it->is_regular_file(type_ec) && IsPhotoFile(it->path())) files.push_back(it->path());
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) {
    set.skipped = dir + ": no images";
    return set;
  }
  const std::vector<size_t> picks = SpreadSample(files.size(), cap);
  for (size_t i : picks)
    AddImageQuery(files[i], fs::relative(files[i], dir).string(), options, &set);
  set.description = std::to_string(picks.size()) + " of " + std::to_string(files.size()) +
                    " real photos under " + dir;
  return set;
}

// The photo-like renders (photo = true) or the clean label renders of a test set.
inline QuerySet TestSetQuerySet(const TestSet* testset,
                                bool photo,
                                int cap,
                                const ImageEdgeOptions& options) {
  namespace fs = std::filesystem;
  QuerySet set;
  set.key = photo ? "testset-photo" : "testset-clean";
  if (testset == nullptr) {
    set.skipped = "no --testset DIR (made by `handdb testset`, docs/evaluation.md)";
    return set;
  }
  std::vector<const TestView*> views;
  for (const TestView& v : testset->views) {
    if (!photo || !v.photo.empty()) views.push_back(&v);
  }
  if (views.empty()) {
    set.skipped = testset->dir.string() + ": no photos (made with --no-photos)";
    return set;
  }
  const std::vector<size_t> picks = SpreadSample(views.size(), cap);
  for (size_t i : picks) {
    const fs::path& file = photo ? views[i]->photo : views[i]->label;
    AddImageQuery(file, fs::relative(file, testset->dir).string(), options, &set);
  }
  set.description = std::to_string(picks.size()) + " of " + std::to_string(views.size()) +
                    (photo ? " photo-like renders (" : " clean label renders (") +
                    (testset->clutter ? "cluttered" : "plain") + " background) of test set " +
                    testset->dir.string();
  return set;
}

// The image sets every benchmark measures, in this order: `photos` (the development photos),
// then the photo-like and the clean renders of the test set in `testset_dir` (skipped with the
// reason when it is empty), at most `cap` queries each. An unreadable test set is an error.
inline Result<std::vector<QuerySet>> ImageQuerySets(const std::string& photos,
                                                    const std::string& testset_dir,
                                                    int cap,
                                                    const ImageEdgeOptions& options) {
  std::optional<TestSet> testset;
  if (!testset_dir.empty()) {
    auto read = ReadTestSet(testset_dir);
    if (!read.ok()) return read.status();
    testset = std::move(read).value();
  }
  const TestSet* ts = testset ? &*testset : nullptr;
  std::vector<QuerySet> sets;
  sets.push_back(PhotoQuerySet(photos, cap, options));
  sets.push_back(TestSetQuerySet(ts, /*photo=*/true, cap, options));
  sets.push_back(TestSetQuerySet(ts, /*photo=*/false, cap, options));
  return sets;
}

// A query near virtual view (v, r): rotated by up to 0.4 roll steps, shifted by up to 2 px, 20%
// of the points dropped, 0.5 px jitter.
inline std::vector<Point2f> PerturbedView(const Database& db,
                                          std::mt19937* rng,
                                          view_id_t* v,
                                          roll_id_t* r) {
  std::uniform_int_distribution<uint32_t> view(0, static_cast<uint32_t>(db.num_views() - 1));
  std::uniform_int_distribution<uint32_t> roll(0, db.num_rolls() - 1);
  std::uniform_real_distribution<float> u(-1, 1);
  *v = view(*rng);
  *r = roll(*rng);
  const auto base = testing::RolledView(db, *v, *r);
  const float extra = 0.4f * u(*rng) * static_cast<float>(2 * M_PI / db.num_rolls());
  const float c = std::cos(extra), s = std::sin(extra);
  const float dx = 2 * u(*rng), dy = 2 * u(*rng);
  std::vector<Point2f> q;
  for (const auto& p : base) {
    if (u(*rng) < -0.6f) continue;
    q.push_back({c * p.x - s * p.y + dx + 0.5f * u(*rng), s * p.x + c * p.y + dy + 0.5f * u(*rng)});
  }
  return q;
}

inline QuerySet PerturbedQuerySet(const Database& db, int count, uint32_t seed) {
  QuerySet set;
  set.key = "perturbed";
  std::mt19937 rng(seed);
  for (int i = 0; i < count; ++i) {
    view_id_t v = 0;
    roll_id_t r = 0;
    set.points.push_back(PerturbedView(db, &rng, &v, &r));
    set.names.push_back("view " + std::to_string(v) + " roll " + std::to_string(r));
  }
  set.description =
      std::to_string(count) + " database views, perturbed (seed " + std::to_string(seed) + ")";
  return set;
}

// `handdb query`'s input options for a database: the defaults, and for label EXRs the edge
// options its manifest records.
inline Result<ImageEdgeOptions> QueryInputOptions(const Database& db) {
  ImageEdgeOptions options;
  auto recorded = DatabaseViewConversionFromMetadata(db.manifest().metadata, db.path().string());
  if (!recorded.ok()) return recorded.status();
  options.label_edges = recorded->edges;
  options.label_joint_pairs = recorded->joint_pairs;
  return options;
}

// Recall@k of `got` against the exact top-k `want`: the share of want's first k (view, roll,
// hand) found among got's first k.
inline double RecallAt(const std::vector<Match>& got, const std::vector<Match>& want, size_t k) {
  const size_t n = std::min(k, want.size());
  if (n == 0) return 1.0;
  size_t found = 0;
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = 0; j < std::min(k, got.size()); ++j) {
      if (got[j].view_id == want[i].view_id && got[j].roll == want[i].roll &&
          got[j].hand == want[i].hand) {
        ++found;
        break;
      }
    }
  }
  return static_cast<double>(found) / static_cast<double>(n);
}

}  // namespace handdb::bench
