// Index study (docs/index.md): how well do cheap per-(view, roll) scores rank the exact top-10, per
// query set? For every query (both hands) the exact top-10 (Searcher, cached in --cache), then for
// every (view, roll, hand) of the database several scores, and the rank each exact top-10 pair
// gets under each score: "candidates needed" for recall@10 = 1 is the largest of those ranks + 1.
//
// Scores (8 px cells of format/coarse_field.h; n_X(c) the points of X in cell c):
//   LA      = sum_c n_Q(c) F_v(c) / |Q|                   the exact coarse A bound (docs/query.md)
//   bound   = LA + sum_c n_Y(c) F_Q(c) / |Y|              + the coarse B bound (both exact bounds)
//   approx  = sum_c n_Q(c) G_v(c) / |Q| + sum_c n_Y(c) G_Q(c) / |Y|, G = the distance from the
//             cell's centre to the set: an approximate D_c, not a bound
//   pcaD    = approx with [G_v ; w n_Y / |Y|] projected by PCA to D dimensions
// and, for the exact branch-and-bound design, the number of pairs whose bound or LA is <= the
// exact 10th best (no exact method using these bounds can skip them).
//
//   index_study --db DIR [--photos DIR] [--testset DIR] [--set-queries 20] [--perturbed 10]
//               [--threads 2] [--pca 32,64] [--pca-sample 8000] [--cache FILE] [--sets a,b]
#include <Eigen/Dense>
#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>

#include "base/thread_pool.h"
#include "bench/bench_args.h"
#include "bench/query_sets.h"
#include "format/coarse_field.h"
#include "query/chamfer.h"
#include "query/coarse_bound.h"
#include "query/distance_transform.h"

namespace handdb {
namespace {

using bench::Median;
using bench::NowSeconds;
using bench::QuerySet;

constexpr int kSide = CoarseGrid::kSide;
constexpr int kCells = CoarseGrid::kCells;

struct Args {
  std::string db, testset, cache;
  std::string photos = bench::DefaultPhotoDir();
  int set_queries = 20;
  int perturbed = 10;
  int threads = 2;
  std::vector<int> pca;
  int pca_sample = 8000;
  std::vector<std::string> sets;
};

// G: the distance (1/2 px, floored, saturating at 255) from each cell's centre to the set, from a
// 1 px distance grid (exact at nodes; the centres are nodes).
void CentreField(std::span<const PointQ> pts, DistanceGrid* grid, uint8_t* out) {
  grid->Build(pts);
  for (int iy = 0; iy < kSide; ++iy) {
    for (int ix = 0; ix < kSide; ++ix) {
      const int cx = -CoarseGrid::kHalfUnits + CoarseGrid::kCellUnits * ix + 64;
      const int cy = -CoarseGrid::kHalfUnits + CoarseGrid::kCellUnits * iy + 64;
      const float d = grid->NodeDistance(grid->NodeIndex(cx), grid->NodeIndex(cy));
      out[iy * kSide + ix] = static_cast<uint8_t>(std::min(255.0f, std::floor(2 * d)));
    }
  }
}

struct Sparse {
  std::vector<uint16_t> cells;
  std::vector<uint16_t> counts;
  uint32_t n = 0;
  void Build(std::span<const PointQ> pts) {
    std::map<int, int> m;
    for (const PointQ& p : pts) {
      const int c = CoarseGrid::CellOf(p);
      if (c >= 0) ++m[c];
    }
    cells.clear();
    counts.clear();
    for (auto [c, k] : m) {
      cells.push_back(static_cast<uint16_t>(c));
      counts.push_back(static_cast<uint16_t>(k));
    }
    n = static_cast<uint32_t>(pts.size());
  }
  double Dot(const uint8_t* field) const {
    return DotAt([field](int c) { return field[c]; });
  }
  // The same over a field read cell by cell (CoarseFields stores them cell-major in blocks).
  template <typename ValueAt>
  double DotAt(ValueAt value_at) const {
    uint64_t s = 0;
    for (size_t i = 0; i < cells.size(); ++i) s += uint64_t{counts[i]} * value_at(cells[i]);
    return static_cast<double>(s) / 2.0 / static_cast<double>(n);
  }
};

struct ExactResult {
  std::vector<Match> top;  // view_id, roll, hand, distance
  double seconds = 0;
};

// --cache: one line per query, "set<TAB>name<TAB>points<TAB>seconds<TAB>v r h d ...".
std::map<std::string, ExactResult> ReadCache(const std::string& file) {
  std::map<std::string, ExactResult> out;
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string set, name, npts;
    std::getline(ss, set, '\t');
    std::getline(ss, name, '\t');
    std::getline(ss, npts, '\t');
    ExactResult r;
    ss >> r.seconds;
    uint32_t v, roll;
    int h;
    double d;
    while (ss >> v >> roll >> h >> d) {
      Match m;
      m.view_id = v;
      m.roll = roll;
      m.hand = h ? Hand::kLeft : Hand::kRight;
      m.distance = d;
      r.top.push_back(m);
    }
    out[set + "\t" + name + "\t" + npts] = r;
  }
  return out;
}

void AppendCache(const std::string& file, const std::string& key, const ExactResult& r) {
  if (file.empty()) return;
  std::ofstream out(file, std::ios::app);
  out << key << "\t" << r.seconds;
  for (const Match& m : r.top) {
    out << " " << m.view_id << " " << m.roll << " " << (m.hand == Hand::kLeft ? 1 : 0) << " ";
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%.17g", m.distance);
    out << buf;
  }
  out << "\n";
}

struct Pca {
  int dims = 0;
  float w = 1;              // weight of the histogram half
  std::vector<float> mean;  // 2 * kCells
  bool whiten = false;
  std::vector<float> comp;   // dims x 2 kCells: e -> z
  std::vector<float> qcomp;  // dims x 2 kCells: u -> its projection
  std::vector<float> z;      // views x dims
};

int Run(const Args& args) {
  auto searcher_or = Searcher::Open(args.db);
  if (!searcher_or.ok()) {
    std::fprintf(stderr, "index_study: %s\n", searcher_or.status().ToString().c_str());
    return 1;
  }
  const Searcher& searcher = **searcher_or;
  const Database& db = searcher.database();
  const size_t nv = db.num_views();
  const uint32_t R = db.num_rolls();
  std::printf("database %s: %zu views x %u rolls = %" PRIu64 " virtual views\n",
              args.db.c_str(),
              nv,
              R,
              db.num_virtual_views());

  // Per view: F (coarse field), G (centre field), sparse histogram.
  double t0 = NowSeconds();
  const CoarseFields coarse(db, args.threads);
  std::vector<uint8_t> g(nv * kCells);
  std::vector<Sparse> hist(nv);
  {
    std::vector<DistanceGrid> grids(args.threads, DistanceGrid(DistanceGridOptions{1.0f, 172.0f}));
    ParallelFor(nv, args.threads, [&](size_t v, int w) {
      const auto pts = db.points(static_cast<view_id_t>(v));
      if (!pts.empty()) CentreField(pts, &grids[w], g.data() + v * kCells);
      hist[v].Build(pts);
      return true;
    });
  }
  std::printf("per-view fields: %.1f s\n", NowSeconds() - t0);

  // PCA of e_v = [G_v (px) ; w h_v] (plain), or in the space whitened by the second moment of
  // query vectors u = [h_Q ; G_Q / w] ("wpca": minimises the error of the inner products
  // <u, e_v> for queries like the database's own rolled views instead of the error of e_v).
  constexpr int D = 2 * kCells;
  std::vector<Pca> pcas;
  auto view_vector = [&](size_t v, float w, float* e) {
    for (int c = 0; c < kCells; ++c) e[c] = g[v * kCells + c] / 2.0f;
    std::fill(e + kCells, e + D, 0.0f);
    const Sparse& h = hist[v];
    for (size_t k = 0; k < h.cells.size(); ++k)
      e[kCells + h.cells[k]] = w * static_cast<float>(h.counts[k]) / static_cast<float>(h.n);
  };
  auto query_vector = [&](const Sparse& hq, const uint8_t* gq, float w, float* u) {
    std::fill(u, u + D, 0.0f);
    for (size_t k = 0; k < hq.cells.size(); ++k)
      u[hq.cells[k]] = static_cast<float>(hq.counts[k]) / static_cast<float>(hq.n);
    for (int c = 0; c < kCells; ++c) u[kCells + c] = gq[c] / 2.0f / w;
  };
  for (int spec : args.pca) {
    const bool whiten = spec < 0;
    const int dims = std::abs(spec);
    t0 = NowSeconds();
    Pca p;
    p.dims = dims;
    p.whiten = whiten;
    const size_t m = std::min<size_t>(nv, static_cast<size_t>(args.pca_sample));
    Eigen::MatrixXd x(static_cast<Eigen::Index>(m), D);
    std::vector<float> row(D);
    for (size_t i = 0; i < m; ++i) {
      view_vector(i * nv / m, 1.0f, row.data());
      for (int j = 0; j < D; ++j) x(static_cast<Eigen::Index>(i), j) = row[j];
    }
    Eigen::RowVectorXd mu = x.colwise().mean();
    double vf = 0, vh = 0;
    for (int j = 0; j < D; ++j) {
      const double var = (x.col(j).array() - mu(j)).square().mean();
      (j < kCells ? vf : vh) += var;
    }
    p.w = static_cast<float>(std::sqrt(vf / vh));
    x.rightCols(kCells) *= p.w;
    mu = x.colwise().mean();
    x.rowwise() -= mu;
    Eigen::MatrixXd wm = Eigen::MatrixXd::Identity(D, D), wi = wm;
    if (whiten) {
      // Query second moment from the database's views at random rolls (both hands).
      std::mt19937 rng(7);
      Eigen::MatrixXd uu(static_cast<Eigen::Index>(m), D);
      DistanceGrid grid(DistanceGridOptions{1.0f, 172.0f});
      std::vector<uint8_t> gq(kCells);
      for (size_t i = 0; i < m; ++i) {
        const view_id_t v = static_cast<view_id_t>((i * nv / m + nv / (2 * m)) % nv);
        auto pts = testing::RolledView(db, v, static_cast<roll_id_t>(rng() % R));
        if (i % 2)
          for (auto& q : pts) q.x = -q.x;
        const auto qq = Quantise(pts);
        Sparse hq;
        hq.Build(qq);
        CentreField(qq, &grid, gq.data());
        query_vector(hq, gq.data(), p.w, row.data());
        for (int j = 0; j < D; ++j) uu(static_cast<Eigen::Index>(i), j) = row[j];
      }
      const Eigen::MatrixXd cu = uu.transpose() * uu / static_cast<double>(m);
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ce(cu);
      const double lmax = ce.eigenvalues().maxCoeff();
      Eigen::VectorXd s = ce.eigenvalues().cwiseMax(1e-6 * lmax).cwiseSqrt();
      wm = ce.eigenvectors() * s.asDiagonal() * ce.eigenvectors().transpose();
      wi = ce.eigenvectors() * s.cwiseInverse().asDiagonal() * ce.eigenvectors().transpose();
      x = x * wm;
    }
    const Eigen::MatrixXd cov = x.transpose() * x / static_cast<double>(m);
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(cov);
    p.mean.resize(D);
    for (int j = 0; j < D; ++j) p.mean[j] = static_cast<float>(mu(j));
    // Codes z = V^T W (e - mu); query projection q = V^T W^-1 u.
    Eigen::MatrixXd v(D, dims);
    double kept = 0, total = eig.eigenvalues().sum();
    for (int k = 0; k < dims; ++k) {
      kept += eig.eigenvalues()(D - 1 - k);
      v.col(k) = eig.eigenvectors().col(D - 1 - k);
    }
    const Eigen::MatrixXd enc = v.transpose() * wm;   // dims x D
    const Eigen::MatrixXd qenc = v.transpose() * wi;  // dims x D
    p.comp.resize(static_cast<size_t>(dims) * D);
    p.qcomp.resize(static_cast<size_t>(dims) * D);
    for (int k = 0; k < dims; ++k)
      for (int j = 0; j < D; ++j) {
        p.comp[static_cast<size_t>(k) * D + j] = static_cast<float>(enc(k, j));
        p.qcomp[static_cast<size_t>(k) * D + j] = static_cast<float>(qenc(k, j));
      }
    p.z.resize(nv * dims);
    ParallelFor(nv, args.threads, [&](size_t vi, int) {
      std::vector<float> e(D);
      view_vector(vi, p.w, e.data());
      for (int j = 0; j < D; ++j) e[j] -= p.mean[j];
      for (int k = 0; k < dims; ++k) {
        double s = 0;
        const float* r = p.comp.data() + static_cast<size_t>(k) * D;
        for (int j = 0; j < D; ++j) s += static_cast<double>(r[j]) * e[j];
        p.z[vi * dims + k] = static_cast<float>(s);
      }
      return true;
    });
    std::printf("%spca %d dims: w %.3f, variance kept %.4f, %.1f s\n",
                whiten ? "w" : "",
                dims,
                p.w,
                kept / total,
                NowSeconds() - t0);
    pcas.push_back(std::move(p));
  }

  // Query sets.
  auto input = bench::QueryInputOptions(db);
  if (!input.ok()) {
    std::fprintf(stderr, "index_study: %s\n", input.status().ToString().c_str());
    return 1;
  }
  auto images = bench::ImageQuerySets(args.photos, args.testset, args.set_queries, *input);
  if (!images.ok()) {
    std::fprintf(stderr, "index_study: %s\n", images.status().ToString().c_str());
    return 1;
  }
  std::vector<QuerySet> sets = std::move(images).value();
  sets.push_back(bench::PerturbedQuerySet(db, args.perturbed, 12345));

  auto cache = ReadCache(args.cache);
  const std::vector<std::string> score_names = [&] {
    std::vector<std::string> n = {"LA", "bound", "approx"};
    for (const Pca& p : pcas) n.push_back((p.whiten ? "wpca" : "pca") + std::to_string(p.dims));
    return n;
  }();
  const size_t ns = score_names.size();
  const std::vector<size_t> budgets = {1000, 3000, 10000, 30000, 100000};

  for (const QuerySet& set : sets) {
    if (!args.sets.empty() &&
        std::find(args.sets.begin(), args.sets.end(), set.key) == args.sets.end()) {
      continue;
    }
    if (!set.skipped.empty()) {
      std::printf("\n%s: skipped (%s)\n", set.key.c_str(), set.skipped.c_str());
      continue;
    }
    std::printf("\n== %s: %s\n", set.key.c_str(), set.description.c_str());
    std::vector<std::vector<double>> needed(ns);
    std::vector<std::vector<std::vector<double>>> recall(
        ns, std::vector<std::vector<double>>(budgets.size()));
    std::vector<double> exact_s, tau, below_la, below_bound;
    for (size_t qi = 0; qi < set.points.size(); ++qi) {
      const auto& q = set.points[qi];
      const std::string key = set.key + "\t" + set.names[qi] + "\t" + std::to_string(q.size());
      ExactResult ex;
      if (auto it = cache.find(key); it != cache.end()) {
        ex = it->second;
      } else {
        SearchOptions o;
        o.hand = Hand::kEither;
        o.num_threads = args.threads;
        o.top_k = 10;
        const double s0 = NowSeconds();
        auto res = searcher.Search(q, o);
        ex.seconds = NowSeconds() - s0;
        if (!res.ok()) {
          std::fprintf(stderr, "index_study: %s\n", res.status().ToString().c_str());
          return 1;
        }
        ex.top = *res;
        AppendCache(args.cache, key, ex);
      }
      exact_s.push_back(ex.seconds);
      const double t = ex.top.back().distance;
      tau.push_back(t);
      // Scores of every pair, both hands: [hand][r * nv + v].
      std::vector<std::vector<float>> score(ns, std::vector<float>(2 * R * nv));
      std::atomic<uint64_t> n_la{0}, n_bound{0};
      for (int hand = 0; hand < 2; ++hand) {
        std::vector<Point2f> pts = q;
        if (hand == 1)
          for (auto& p : pts) p.x = -p.x;
        std::vector<DistanceGrid> grids(args.threads,
                                        DistanceGrid(DistanceGridOptions{1.0f, 172.0f}));
        ParallelFor(R, args.threads, [&](size_t r, int w) {
          const auto rolled = RotateAndQuantise(pts, -RollAngle(static_cast<roll_id_t>(r), R));
          Sparse hq;
          hq.Build(rolled);
          std::vector<uint8_t> fq(kCells), gq(kCells);
          ComputeCoarseField(rolled, fq.data());
          CentreField(rolled, &grids[w], gq.data());
          // PCA query vectors: u = [h_Q ; G_Q / w]; score = <u, mean> + <P u, z_v>.
          std::vector<std::vector<float>> pu(pcas.size());
          std::vector<double> off(pcas.size());
          for (size_t pi = 0; pi < pcas.size(); ++pi) {
            const Pca& p = pcas[pi];
            std::vector<float> u(D);
            query_vector(hq, gq.data(), p.w, u.data());
            double o = 0;
            for (int j = 0; j < D; ++j) o += static_cast<double>(u[j]) * p.mean[j];
            off[pi] = o;
            pu[pi].resize(p.dims);
            for (int k = 0; k < p.dims; ++k) {
              double s = 0;
              const float* row = p.qcomp.data() + static_cast<size_t>(k) * D;
              for (int j = 0; j < D; ++j) s += static_cast<double>(row[j]) * u[j];
              pu[pi][k] = static_cast<float>(s);
            }
          }
          uint64_t la_n = 0, b_n = 0;
          for (size_t v = 0; v < nv; ++v) {
            const size_t idx = (static_cast<size_t>(hand) * R + r) * nv + v;
            const double la = hq.DotAt([&](int c) { return coarse.value(v, c); });
            const double lb = hist[v].Dot(fq.data());
            const double aa = hq.Dot(g.data() + v * kCells);
            const double ab = hist[v].Dot(gq.data());
            score[0][idx] = static_cast<float>(la);
            score[1][idx] = static_cast<float>(la + lb);
            score[2][idx] = static_cast<float>(aa + ab);
            for (size_t pi = 0; pi < pcas.size(); ++pi) {
              const Pca& p = pcas[pi];
              double s = off[pi];
              const float* z = p.z.data() + v * p.dims;
              for (int k = 0; k < p.dims; ++k) s += static_cast<double>(pu[pi][k]) * z[k];
              score[3 + pi][idx] = static_cast<float>(s);
            }
            la_n += la <= t;
            b_n += la + lb <= t;
          }
          n_la += la_n;
          n_bound += b_n;
          return true;
        });
      }
      below_la.push_back(static_cast<double>(n_la.load()));
      below_bound.push_back(static_cast<double>(n_bound.load()));
      // Ranks of the exact top-10 under each score.
      std::string line;
      for (size_t si = 0; si < ns; ++si) {
        const auto& s = score[si];
        std::vector<float> th;
        for (const Match& m : ex.top) {
          th.push_back(
              s[(static_cast<size_t>(m.hand == Hand::kLeft) * R + m.roll) * nv + m.view_id]);
        }
        std::vector<uint64_t> rank(th.size(), 0);
        for (float x : s)
          for (size_t k = 0; k < th.size(); ++k) rank[k] += x <= th[k];
        const uint64_t worst = *std::max_element(rank.begin(), rank.end());
        needed[si].push_back(static_cast<double>(worst));
        for (size_t b = 0; b < budgets.size(); ++b) {
          size_t in = 0;
          for (uint64_t rk : rank) in += rk <= budgets[b];
          recall[si][b].push_back(static_cast<double>(in) / static_cast<double>(rank.size()));
        }
        char buf[64];
        std::snprintf(buf, sizeof(buf), " %s %" PRIu64, score_names[si].c_str(), worst);
        line += buf;
      }
      std::printf(
          "  %-40s d1 %.2f d10 %.2f exact %.2f s | LA<=d10 %.0f bound<=d10 %.0f | need:%s\n",
          set.names[qi].c_str(),
          ex.top.front().distance,
          t,
          ex.seconds,
          below_la.back(),
          below_bound.back(),
          line.c_str());
      std::fflush(stdout);
    }
    const double pairs = 2.0 * R * static_cast<double>(nv);
    std::printf(
        "  summary: exact median %.2f s; d10 median %.2f; pairs with LA <= d10: median %.0f "
        "(%.3f%%) max %.0f; bound <= d10: median %.0f (%.3f%%) max %.0f\n",
        Median(exact_s),
        Median(tau),
        Median(below_la),
        100 * Median(below_la) / pairs,
        *std::max_element(below_la.begin(), below_la.end()),
        Median(below_bound),
        100 * Median(below_bound) / pairs,
        *std::max_element(below_bound.begin(), below_bound.end()));
    for (size_t si = 0; si < ns; ++si) {
      std::printf("  %-8s candidates for recall@10 = 1: median %.0f max %.0f; recall@10 at",
                  score_names[si].c_str(),
                  Median(needed[si]),
                  *std::max_element(needed[si].begin(), needed[si].end()));
      for (size_t b = 0; b < budgets.size(); ++b) {
        double mean = 0;
        for (double x : recall[si][b]) mean += x / static_cast<double>(recall[si][b].size());
        std::printf(" %zu: %.3f", budgets[b], mean);
      }
      std::printf("\n");
    }
  }
  return 0;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  handdb::Args args;
  CLI::App app("How cheap scores rank the exact top-10 per query set (docs/index.md).",
               "index_study");
  handdb::bench::AddQuerySetFlags(app, args);
  app.add_option("--cache", args.cache, "exact results cache (read, then extended)");
  app.add_option("--perturbed", args.perturbed, "perturbed database views")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  handdb::bench::AddList(app, "--pca", args.pca, "PCA dimensions, N,M");
  app.add_option("--pca-sample", args.pca_sample, "views sampled for the PCA")
      ->capture_default_str();
  handdb::bench::AddList(app, "--sets", args.sets, "query sets to study, a,b (default all)");
  if (int rc = handdb::bench::ParseBenchArgs(app, argc, argv); rc >= 0) return rc;
  if (args.db.empty()) {
    std::fprintf(stderr, "index_study: --db DIR is required\n");
    return 2;
  }
  return handdb::Run(args);
}
