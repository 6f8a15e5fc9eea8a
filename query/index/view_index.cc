#include "query/index/view_index.h"

#include <faiss/Clustering.h>
#include <faiss/IndexFlat.h>
#include <faiss/impl/FaissException.h>
#include <omp.h>
#include <xxhash.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "base/atomic_file.h"
#include "base/endian.h"
#include "base/hex.h"
#include "base/progress.h"
#include "base/thread_pool.h"
#include "query/chamfer.h"
#include "query/database.h"
#include "query/index/code_scan.h"
#include "query/index/embedding.h"

namespace handdb {
namespace {

constexpr char kMagic[8] = {'H', 'D', 'B', 'I', 'N', 'D', 'E', 'X'};
constexpr uint16_t kMajor = 1;
constexpr uint16_t kMinor = 0;
constexpr uint32_t kHeaderSize = 128;
constexpr uint64_t kFaissSeed = 1234;

// Header field offsets (docs/index.md, "File layout"). Little-endian.
constexpr size_t kOffMajor = 8, kOffMinor = 10, kOffHeaderSize = 12, kOffFileSize = 16,
                 kOffFingerprint = 24, kOffViews = 32, kOffRolls = 40, kOffCellUnits = 44,
                 kOffDims = 48, kOffNlist = 52, kOffWeight = 56, kOffSide = 60,
                 kOffPayloadOffset = 64, kOffPayloadSize = 72, kOffPayloadChecksum = 80,
                 kOffReserved = 88, kOffHeaderChecksum = 120;

Status Corrupt(StatusCode code, const std::string& what, const std::string& problem) {
  return Status(code, what + ": " + problem);
}

// An even sample of at most n of [0, total).
std::vector<view_id_t> EvenSample(size_t total, size_t n) {
  std::vector<view_id_t> out;
  const size_t m = std::min(total, n);
  out.reserve(m);
  for (size_t i = 0; i < m; ++i) out.push_back(static_cast<view_id_t>(i * total / m));
  return out;
}

int Threads(int requested) { return ResolveNumThreads(requested); }

// OpenMP's thread count for the regions this thread starts (FAISS's k-means and assignment)
// while the guard lives, restored after: the count is an ICV of the calling thread, so no other
// thread and nothing after the build sees a change.
class ScopedOmpThreads {
 public:
  explicit ScopedOmpThreads(int n) : saved_(omp_get_max_threads()) { omp_set_num_threads(n); }
  ~ScopedOmpThreads() { omp_set_num_threads(saved_); }
  ScopedOmpThreads(const ScopedOmpThreads&) = delete;
  ScopedOmpThreads& operator=(const ScopedOmpThreads&) = delete;

 private:
  int saved_;
};

}  // namespace

uint64_t DatabaseFingerprint(const Manifest& manifest) {
  std::string text = "rolls=" + std::to_string(manifest.rolls) + "\n";
  for (const ManifestShard& s : manifest.shards) {
    text += ShardFinalFileName(s.file) + " " + std::to_string(s.views) + " " + s.xxh3 + "\n";
  }
  return XXH3_64bits(text.data(), text.size());
}

bool IndexBuildOptions::Check(std::string* error) const {
  if (!grid.Check(error)) return false;
  if (dims < 1 || dims > grid.dims()) {
    *error = "--dims must be in [1, " + std::to_string(grid.dims()) + "]";
    return false;
  }
  if (nlist < 0) {
    *error = "--nlist must be >= 0 (0: automatic)";
    return false;
  }
  if (train_views < 1) {
    *error = "--train-views must be >= 1";
    return false;
  }
  return true;
}

ViewIndex::ViewIndex() = default;
ViewIndex::~ViewIndex() = default;
ViewIndex::ViewIndex(ViewIndex&&) noexcept = default;
ViewIndex& ViewIndex::operator=(ViewIndex&&) noexcept = default;

Result<ViewIndex> ViewIndex::Build(const Database& db, const IndexBuildOptions& options) {
  std::string error;
  if (!options.Check(&error)) return Status(StatusCode::kInvalidArgument, error);
  if (db.num_views() == 0) {
    return Status(StatusCode::kInvalidArgument, db.path().string() + ": no views to index");
  }
  const auto start = std::chrono::steady_clock::now();
  const int threads = Threads(options.num_threads);
  // Eigen's products here never start threads (EIGEN_DONT_PARALLELIZE for this file,
  // query/CMakeLists.txt): one thread keeps the sums in one order, so the file is the same for
  // any --threads.
  const EmbeddingGrid& grid = options.grid;
  const int D = grid.dims();
  const int H = grid.cells();
  const size_t n = db.num_views();
  const uint32_t rolls = db.num_rolls();
  ViewIndex index;
  index.dims_ = options.dims;
  index.grid_ = grid;
  index.num_views_ = n;
  index.num_rolls_ = rolls;
  index.fingerprint_ = DatabaseFingerprint(db.manifest());
  index.nlist_ =
      options.nlist > 0
          ? std::min<int>(options.nlist, static_cast<int>(n))
          : std::clamp(
                static_cast<int>(4 * std::sqrt(static_cast<double>(n))), 1, static_cast<int>(n));

  // 1. The training sample: view vectors e (w = 1 first, to choose w) and query vectors u of the
  //    same views at a roll and hand picked by a fixed rule (the index sees no real queries).
  const std::vector<view_id_t> sample = EvenSample(n, static_cast<size_t>(options.train_views));
  const auto m = static_cast<Eigen::Index>(sample.size());
  Eigen::MatrixXd x(m, D);
  std::vector<std::vector<float>> rolled_u(sample.size());
  {
    std::vector<std::vector<float>> rows(sample.size());
    ParallelFor(sample.size(), threads, [&](size_t i, int) {
      const view_id_t v = sample[i];
      rows[i].resize(D);
      std::vector<PointQ> decoded;  // a coded view's points (not kept)
      const std::span<const PointQ> view = db.ViewPoints(v, &decoded);
      ViewVector(grid, view, 1.0f, rows[i].data());
      std::vector<Point2f> pts;
      RollPoints(view, RollAngle(static_cast<roll_id_t>((7 * i + 3) % rolls), rolls), &pts);
      if (i % 2 == 1) {
        for (Point2f& p : pts) p.x = -p.x;
      }
      rolled_u[i].resize(D);
      QueryVector(grid, Quantise(pts), 1.0f, rolled_u[i].data());
      return true;
    });
    for (Eigen::Index i = 0; i < m; ++i) {
      for (int j = 0; j < D; ++j) x(i, j) = rows[static_cast<size_t>(i)][j];
    }
  }
  double var_g = 0, var_h = 0;
  for (int j = 0; j < D; ++j) {
    const double mu = x.col(j).mean();
    (j < H ? var_g : var_h) += (x.col(j).array() - mu).square().mean();
  }
  index.weight_ = var_h > 0 && var_g > 0 ? static_cast<float>(std::sqrt(var_g / var_h)) : 1.0f;
  const double w = index.weight_;
  x.rightCols(H) *= w;
  Eigen::MatrixXd u(m, D);
  for (Eigen::Index i = 0; i < m; ++i) {
    const std::vector<float>& r = rolled_u[static_cast<size_t>(i)];
    for (int j = 0; j < D; ++j) u(i, j) = j < H ? r[j] : r[j] / w;
  }
  rolled_u.clear();

  // 2. W = E[u u^T]^(1/2) (eigenvalues clipped at 1e-6 of the largest), the PCA of W (e - mu),
  //    eigenvector signs fixed (largest entry > 0).
  const Eigen::MatrixXd cu = (u.transpose() * u) / static_cast<double>(m);
  u.resize(0, 0);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> whiten(cu);
  if (whiten.info() != Eigen::Success) {
    return Status(StatusCode::kInvalidArgument, db.path().string() + ": PCA did not converge");
  }
  const double lmax = std::max(whiten.eigenvalues().maxCoeff(), 1e-300);
  const Eigen::VectorXd root = whiten.eigenvalues().cwiseMax(1e-6 * lmax).cwiseSqrt();
  const Eigen::MatrixXd wm =
      whiten.eigenvectors() * root.asDiagonal() * whiten.eigenvectors().transpose();
  const Eigen::MatrixXd wi =
      whiten.eigenvectors() * root.cwiseInverse().asDiagonal() * whiten.eigenvectors().transpose();
  const Eigen::RowVectorXd mean = x.colwise().mean();
  x.rowwise() -= mean;
  const Eigen::MatrixXd xw = x * wm;
  x.resize(0, 0);
  const Eigen::MatrixXd cov = (xw.transpose() * xw) / static_cast<double>(m);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(cov);
  if (eig.info() != Eigen::Success) {
    return Status(StatusCode::kInvalidArgument, db.path().string() + ": PCA did not converge");
  }
  const int d = options.dims;
  Eigen::MatrixXd v(D, d);
  for (int k = 0; k < d; ++k) {
    Eigen::VectorXd c = eig.eigenvectors().col(D - 1 - k);  // ascending eigenvalues
    Eigen::Index arg = 0;
    c.cwiseAbs().maxCoeff(&arg);
    if (c(arg) < 0) c = -c;
    v.col(k) = c;
  }
  const Eigen::MatrixXd encode = v.transpose() * wm;  // d x D
  const Eigen::MatrixXd project = v.transpose() * wi;
  index.mean_.resize(D);
  for (int j = 0; j < D; ++j) index.mean_[j] = static_cast<float>(mean(j));
  index.query_projection_.resize(static_cast<size_t>(d) * D);
  std::vector<float> enc(static_cast<size_t>(d) * D);
  for (int k = 0; k < d; ++k) {
    for (int j = 0; j < D; ++j) {
      index.query_projection_[static_cast<size_t>(k) * D + j] = static_cast<float>(project(k, j));
      enc[static_cast<size_t>(k) * D + j] = static_cast<float>(encode(k, j));
    }
  }

  // Every view encoded (in parallel, each view on its own: deterministic).
  std::vector<float> z(n * static_cast<size_t>(d));
  {
    Progress progress("index embed", n, options.progress, "views");
    ParallelFor(n, threads, [&](size_t vi, int) {
      std::vector<float> e(D);
      thread_local std::vector<PointQ> decoded;  // a coded view's points (not kept)
      ViewVector(
          grid, db.ViewPoints(static_cast<view_id_t>(vi), &decoded), index.weight_, e.data());
      for (int j = 0; j < D; ++j) e[j] -= index.mean_[j];
      float* out = z.data() + vi * static_cast<size_t>(d);
      for (int k = 0; k < d; ++k) {
        const float* row = enc.data() + static_cast<size_t>(k) * D;
        double s = 0;
        for (int j = 0; j < D; ++j) s += static_cast<double>(row[j]) * e[j];
        out[k] = static_cast<float>(s);
      }
      progress.Add();
      return true;
    });
  }

  // 3. IVF lists: FAISS's k-means (L2, fixed seed) on the sample, every view in the list of its
  //    nearest centroid (in increasing view id), lists chosen at query time (--nprobe) by inner
  //    product with the centroids and scanned by inner product. (Turning the inner product into L2
  //    with an extra coordinate sqrt(M^2 - |z|^2) was tried first: M^2 dwarfs the differences that
  //    matter, and the quantizer's |x|^2 + |y|^2 - 2<x, y> in float lost them: recall@10 0.02-0.12
  //    at nprobe = lists / 8.)
  // FAISS's k-means sums in OpenMP chunks: one thread keeps the result independent of --threads.
  const ScopedOmpThreads one_omp_thread(1);
  try {
    std::vector<float> train(sample.size() * static_cast<size_t>(d));
    for (size_t i = 0; i < sample.size(); ++i) {
      std::memcpy(
          train.data() + i * d, z.data() + static_cast<size_t>(sample[i]) * d, sizeof(float) * d);
    }
    faiss::ClusteringParameters cp;
    cp.seed = kFaissSeed;
    cp.verbose = false;
    cp.min_points_per_centroid = 1;  // small databases: no "provide more points" warning
    faiss::Clustering clustering(d, index.nlist_, cp);
    faiss::IndexFlatL2 assign(d);
    clustering.train(static_cast<faiss::Index::idx_t>(sample.size()), train.data(), assign);
    std::vector<faiss::Index::idx_t> list(n);
    std::vector<float> dist(n);
    assign.search(static_cast<faiss::Index::idx_t>(n), z.data(), 1, dist.data(), list.data());
    std::vector<uint32_t> sizes(static_cast<size_t>(index.nlist_), 0);
    for (faiss::Index::idx_t l : list) ++sizes[static_cast<size_t>(l)];
    std::vector<size_t> at(sizes.size(), 0);
    for (size_t l = 1; l < sizes.size(); ++l) at[l] = at[l - 1] + sizes[l - 1];
    std::vector<uint32_t> ids(n);
    std::vector<float> codes(n * static_cast<size_t>(d));
    for (size_t vi = 0; vi < n; ++vi) {
      const size_t slot = at[static_cast<size_t>(list[vi])]++;
      ids[slot] = static_cast<uint32_t>(vi);
      std::memcpy(codes.data() + slot * d, z.data() + vi * d, sizeof(float) * d);
    }
    index.SetLists(std::move(clustering.centroids), std::move(sizes), ids, codes.data());
  } catch (const faiss::FaissException& e) {
    return Status(StatusCode::kInvalidArgument,
                  db.path().string() + ": building the IVF index failed: " + e.what());
  }
  index.build_seconds_ =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return index;
}

// Payload (docs/index.md, "File layout"), little-endian, sizes fixed by the header:
//   mean               D f32
//   query_projection   dims x D f32
//   centroids          nlist x dims f32
//   list_sizes         nlist u32 (summing to num_views)
//   ids                num_views u32, list by list (each view exactly once)
//   codes              num_views x dims f32, in the order of ids
std::string ViewIndex::Serialize() const {
  const size_t d = static_cast<size_t>(dims_);
  std::string payload;
  auto append = [&](const void* p, size_t bytes) {
    payload.append(static_cast<const char*>(p), bytes);
  };
  append(mean_.data(), sizeof(float) * mean_.size());
  append(query_projection_.data(), sizeof(float) * query_projection_.size());
  append(centroids_.data(), sizeof(float) * centroids_.size());
  const std::vector<uint32_t>& sizes = list_sizes_;
  std::vector<uint32_t> ids;
  std::vector<float> codes;
  ids.reserve(num_views_);
  codes.reserve(num_views_ * d);
  for (size_t l = 0; l < sizes.size(); ++l) {
    for (size_t slot = list_begin_[l]; slot < list_begin_[l] + sizes[l]; ++slot) {
      ids.push_back(static_cast<uint32_t>(ids_[slot]));
      const float* block = codes_.data() + (slot / kCodeLanes) * d * kCodeLanes;
      for (size_t j = 0; j < d; ++j) codes.push_back(block[j * kCodeLanes + slot % kCodeLanes]);
    }
  }
  append(sizes.data(), sizeof(uint32_t) * sizes.size());
  append(ids.data(), sizeof(uint32_t) * ids.size());
  append(codes.data(), sizeof(float) * codes.size());
  std::string out(kHeaderSize, '\0');
  std::memcpy(out.data(), kMagic, sizeof(kMagic));
  StoreLittleEndian<uint16_t>(out.data() + kOffMajor, kMajor);
  StoreLittleEndian<uint16_t>(out.data() + kOffMinor, kMinor);
  StoreLittleEndian<uint32_t>(out.data() + kOffHeaderSize, kHeaderSize);
  StoreLittleEndian<uint64_t>(out.data() + kOffFileSize, kHeaderSize + payload.size());
  StoreLittleEndian<uint64_t>(out.data() + kOffFingerprint, fingerprint_);
  StoreLittleEndian<uint64_t>(out.data() + kOffViews, num_views_);
  StoreLittleEndian<uint32_t>(out.data() + kOffRolls, num_rolls_);
  StoreLittleEndian<uint32_t>(out.data() + kOffCellUnits, static_cast<uint32_t>(grid_.cell_units));
  StoreLittleEndian<uint32_t>(out.data() + kOffDims, static_cast<uint32_t>(dims_));
  StoreLittleEndian<uint32_t>(out.data() + kOffNlist, static_cast<uint32_t>(nlist_));
  StoreLittleEndian<float>(out.data() + kOffWeight, weight_);
  StoreLittleEndian<uint32_t>(out.data() + kOffSide, static_cast<uint32_t>(grid_.side));
  StoreLittleEndian<uint64_t>(out.data() + kOffPayloadOffset, kHeaderSize);
  StoreLittleEndian<uint64_t>(out.data() + kOffPayloadSize, payload.size());
  StoreLittleEndian<uint64_t>(out.data() + kOffPayloadChecksum,
                              XXH3_64bits(payload.data(), payload.size()));
  StoreLittleEndian<uint64_t>(out.data() + kOffHeaderChecksum,
                              XXH3_64bits(out.data(), kOffHeaderChecksum));
  return out + payload;
}

Result<ViewIndex> ViewIndex::Parse(std::string_view bytes,
                                   uint64_t database_fingerprint,
                                   uint64_t num_views,
                                   uint32_t num_rolls,
                                   const std::string& what) {
  if (bytes.size() < kHeaderSize) {
    return Corrupt(StatusCode::kTruncated,
                   what,
                   std::to_string(bytes.size()) + " bytes, shorter than the " +
                       std::to_string(kHeaderSize) + "-byte index header");
  }
  if (std::memcmp(bytes.data(), kMagic, sizeof(kMagic)) != 0) {
    return Corrupt(StatusCode::kBadMagic, what, "not a handdb index (bad magic)");
  }
  const uint16_t major = LoadLittleEndian<uint16_t>(bytes.data() + kOffMajor);
  if (major != kMajor) {
    return Corrupt(StatusCode::kUnsupportedVersion,
                   what,
                   "index format version " + std::to_string(major) + "." +
                       std::to_string(LoadLittleEndian<uint16_t>(bytes.data() + kOffMinor)) +
                       ", this reader knows " + std::to_string(kMajor) + ".x");
  }
  const uint64_t stored_header_sum = LoadLittleEndian<uint64_t>(bytes.data() + kOffHeaderChecksum);
  const uint64_t header_sum = XXH3_64bits(bytes.data(), kOffHeaderChecksum);
  if (stored_header_sum != header_sum) {
    return Corrupt(StatusCode::kChecksumMismatch,
                   what,
                   "offset " + std::to_string(kOffHeaderChecksum) + ": header checksum " +
                       Hex64(stored_header_sum) + ", computed " + Hex64(header_sum));
  }
  // As for shards (docs/format.md, "Versioning"): any minor of our major is read; reserved bytes
  // must be zero only up to the minor this reader knows, since a newer minor may give them meaning.
  const bool know_minor = LoadLittleEndian<uint16_t>(bytes.data() + kOffMinor) <= kMinor;
  for (size_t off = kOffReserved; know_minor && off < kOffHeaderChecksum; ++off) {
    if (bytes[off] != 0) {
      return Corrupt(StatusCode::kNonZeroReserved,
                     what,
                     "offset " + std::to_string(off) + ": reserved header byte is not zero");
    }
  }
  const uint64_t file_size = LoadLittleEndian<uint64_t>(bytes.data() + kOffFileSize);
  const uint64_t payload_offset = LoadLittleEndian<uint64_t>(bytes.data() + kOffPayloadOffset);
  const uint64_t payload_size = LoadLittleEndian<uint64_t>(bytes.data() + kOffPayloadSize);
  if (file_size != bytes.size()) {
    return Corrupt(
        file_size > bytes.size() ? StatusCode::kTruncated : StatusCode::kSizeMismatch,
        what,
        std::to_string(bytes.size()) + " bytes but the header says " + std::to_string(file_size));
  }
  if (LoadLittleEndian<uint32_t>(bytes.data() + kOffHeaderSize) != kHeaderSize ||
      payload_offset != kHeaderSize || payload_size != file_size - kHeaderSize) {
    return Corrupt(StatusCode::kBadLayout,
                   what,
                   "header size " +
                       std::to_string(LoadLittleEndian<uint32_t>(bytes.data() + kOffHeaderSize)) +
                       ", payload at " + std::to_string(payload_offset) + " of " +
                       std::to_string(payload_size) + " bytes: not the layout of version 1");
  }
  const std::string_view payload = bytes.substr(payload_offset);
  const uint64_t stored_sum = LoadLittleEndian<uint64_t>(bytes.data() + kOffPayloadChecksum);
  const uint64_t sum = XXH3_64bits(payload.data(), payload.size());
  if (stored_sum != sum) {
    return Corrupt(StatusCode::kChecksumMismatch,
                   what,
                   "offset " + std::to_string(payload_offset) + ": payload checksum " +
                       Hex64(stored_sum) + ", computed " + Hex64(sum));
  }
  if (LoadLittleEndian<uint64_t>(bytes.data() + kOffFingerprint) != database_fingerprint) {
    return Corrupt(StatusCode::kSizeMismatch,
                   what,
                   "built for other shards (database fingerprint " +
                       Hex64(LoadLittleEndian<uint64_t>(bytes.data() + kOffFingerprint)) +
                       ", this database " + Hex64(database_fingerprint) +
                       "): rebuild it with `handdb index`");
  }
  ViewIndex index;
  index.fingerprint_ = database_fingerprint;
  index.num_views_ = LoadLittleEndian<uint64_t>(bytes.data() + kOffViews);
  index.num_rolls_ = LoadLittleEndian<uint32_t>(bytes.data() + kOffRolls);
  index.dims_ = static_cast<int>(LoadLittleEndian<uint32_t>(bytes.data() + kOffDims));
  index.nlist_ = static_cast<int>(LoadLittleEndian<uint32_t>(bytes.data() + kOffNlist));
  index.weight_ = LoadLittleEndian<float>(bytes.data() + kOffWeight);
  index.grid_.cell_units =
      static_cast<int>(LoadLittleEndian<uint32_t>(bytes.data() + kOffCellUnits));
  index.grid_.side = static_cast<int>(LoadLittleEndian<uint32_t>(bytes.data() + kOffSide));
  if (index.num_views_ != num_views || index.num_rolls_ != num_rolls) {
    return Corrupt(StatusCode::kSizeMismatch,
                   what,
                   "indexes " + std::to_string(index.num_views_) + " views x " +
                       std::to_string(index.num_rolls_) + " rolls, the database has " +
                       std::to_string(num_views) + " x " + std::to_string(num_rolls));
  }
  if (num_views > std::numeric_limits<uint32_t>::max()) {  // ids are u32
    return Corrupt(StatusCode::kOutOfRange,
                   what,
                   std::to_string(num_views) + " views: more than 32-bit view ids can name");
  }
  std::string grid_error;
  if (!index.grid_.Check(&grid_error) || LoadLittleEndian<uint32_t>(bytes.data() + kOffDims) < 1 ||
      LoadLittleEndian<uint32_t>(bytes.data() + kOffDims) >
          static_cast<uint32_t>(index.grid_.dims()) ||
      LoadLittleEndian<uint32_t>(bytes.data() + kOffNlist) < 1 ||
      LoadLittleEndian<uint32_t>(bytes.data() + kOffNlist) > num_views ||
      !(std::isfinite(index.weight_) && index.weight_ > 0)) {
    return Corrupt(
        StatusCode::kOutOfRange,
        what,
        "embedding parameters out of range (cell " +
            std::to_string(LoadLittleEndian<uint32_t>(bytes.data() + kOffCellUnits)) + ", side " +
            std::to_string(LoadLittleEndian<uint32_t>(bytes.data() + kOffSide)) + ", dims " +
            std::to_string(LoadLittleEndian<uint32_t>(bytes.data() + kOffDims)) + ", lists " +
            std::to_string(LoadLittleEndian<uint32_t>(bytes.data() + kOffNlist)) + ", weight " +
            std::to_string(index.weight_) + ")");
  }
  // Every size below is small (dims <= 20,402, lists <= views < 2^32): no overflow in 64 bits.
  const uint64_t D = static_cast<uint64_t>(index.grid_.dims());
  const uint64_t d = static_cast<uint64_t>(index.dims_);
  const uint64_t lists = static_cast<uint64_t>(index.nlist_);
  const uint64_t expected = 4 * (D + d * D + lists * d + lists + num_views + num_views * d);
  if (payload.size() != expected) {
    return Corrupt(payload.size() < expected ? StatusCode::kTruncated : StatusCode::kSizeMismatch,
                   what,
                   "payload of " + std::to_string(payload.size()) +
                       " bytes, the header's sizes "
                       "need " +
                       std::to_string(expected));
  }
  size_t at = 0;
  auto take_floats = [&](std::vector<float>* out, uint64_t count) {
    out->resize(count);
    std::memcpy(out->data(), payload.data() + at, 4 * count);
    at += 4 * count;
  };
  std::vector<float> centroids, codes;
  std::vector<uint32_t> sizes(lists), ids(num_views);
  take_floats(&index.mean_, D);
  take_floats(&index.query_projection_, d * D);
  take_floats(&centroids, lists * d);
  std::memcpy(sizes.data(), payload.data() + at, 4 * lists);
  at += 4 * lists;
  std::memcpy(ids.data(), payload.data() + at, 4 * num_views);
  at += 4 * num_views;
  take_floats(&codes, num_views * d);
  for (const std::vector<float>* floats :
       {&index.mean_, &index.query_projection_, &centroids, &codes}) {
    for (size_t i = 0; i < floats->size(); ++i) {
      if (!std::isfinite((*floats)[i])) {
        return Corrupt(StatusCode::kOutOfRange, what, "a non-finite value in the payload");
      }
    }
  }
  uint64_t total = 0;
  for (uint32_t s : sizes) total += s;
  if (total != num_views) {
    return Corrupt(StatusCode::kBadLayout,
                   what,
                   "the lists hold " + std::to_string(total) + " views, the database has " +
                       std::to_string(num_views));
  }
  std::vector<bool> seen(num_views, false);
  for (uint32_t id : ids) {
    if (id >= num_views || seen[id]) {
      return Corrupt(StatusCode::kBadLayout,
                     what,
                     "view " + std::to_string(id) +
                         (id >= num_views ? " is out of range" : " is listed twice"));
    }
    seen[id] = true;
  }
  index.SetLists(std::move(centroids), std::move(sizes), ids, codes.data());
  return index;
}

Result<ViewIndex> ViewIndex::Open(const std::filesystem::path& db_dir, const Manifest& manifest) {
  if (!manifest.index) {
    return Status(StatusCode::kNotFound,
                  db_dir.string() + ": the manifest lists no index (build one: handdb index " +
                      db_dir.string() + ")");
  }
  const std::filesystem::path file = db_dir / manifest.index->file;
  auto bytes = ReadFileToString(file);
  if (!bytes.ok()) return bytes.status();
  if (bytes->size() != manifest.index->bytes) {
    return Status(StatusCode::kSizeMismatch,
                  file.string() + ": " + std::to_string(bytes->size()) +
                      " bytes, the manifest says " + std::to_string(manifest.index->bytes));
  }
  const std::string sum = Hex64(XXH3_64bits(bytes->data(), bytes->size()));
  if (sum != manifest.index->xxh3) {
    return Status(
        StatusCode::kChecksumMismatch,
        file.string() + ": checksum " + sum + ", the manifest says " + manifest.index->xxh3);
  }
  return Parse(
      *bytes, DatabaseFingerprint(manifest), manifest.num_views, manifest.rolls, file.string());
}

void ViewIndex::SetLists(std::vector<float> centroids,
                         std::vector<uint32_t> sizes,
                         const std::vector<uint32_t>& ids,
                         const float* codes) {
  const size_t d = static_cast<size_t>(dims_);
  centroids_ = std::move(centroids);
  list_sizes_ = std::move(sizes);
  list_begin_.assign(list_sizes_.size(), 0);
  size_t slots = 0;
  for (size_t l = 0; l < list_sizes_.size(); ++l) {
    list_begin_[l] = slots;
    slots += (list_sizes_[l] + kCodeLanes - 1) / kCodeLanes * kCodeLanes;
  }
  // The query side as one more "list" for the same kernel: rows 0..d-1 of V^T W^-1 and row d the
  // mean, so that one product gives every rolled query's w_r and offset_r.
  const size_t D = static_cast<size_t>(grid_.dims());
  const size_t rows = (d + 1 + kCodeLanes - 1) / kCodeLanes * kCodeLanes;
  query_blocks_.assign(rows * D, 0.0f);
  for (size_t row = 0; row <= d; ++row) {
    const float* from_row = row < d ? query_projection_.data() + row * D : mean_.data();
    float* block = query_blocks_.data() + (row / kCodeLanes) * D * kCodeLanes;
    for (size_t j = 0; j < D; ++j) block[j * kCodeLanes + row % kCodeLanes] = from_row[j];
  }
  ids_.assign(slots, kInvalidViewId);
  codes_.assign(slots * d, 0.0f);
  size_t from = 0;
  for (size_t l = 0; l < list_sizes_.size(); ++l) {
    for (size_t i = 0; i < list_sizes_[l]; ++i, ++from) {
      const size_t slot = list_begin_[l] + i;
      ids_[slot] = ids[from];
      float* block = codes_.data() + (slot / kCodeLanes) * d * kCodeLanes;
      for (size_t j = 0; j < d; ++j)
        block[j * kCodeLanes + slot % kCodeLanes] = codes[from * d + j];
    }
  }
}

namespace {

// The best `k` candidates seen, as a max-heap under `Before` (its front is the worst kept).
class TopCandidates {
 public:
  explicit TopCandidates(size_t k) : k_(k) { heap_.reserve(k); }
  static bool Before(const Candidate& x, const Candidate& y) {
    if (x.score != y.score) return x.score < y.score;
    if (x.view != y.view) return x.view < y.view;
    return x.roll < y.roll;
  }
  // Inner products below this cannot enter for a query with this offset (s = offset - ip):
  // a margin far above float rounding keeps the test conservative; Offer() decides exactly.
  double Floor(double offset) const {
    if (heap_.size() < k_) return -std::numeric_limits<double>::infinity();
    const double limit = offset - static_cast<double>(heap_.front().score);
    return limit - 1e-4 * std::max(1.0, std::abs(limit));
  }
  void Offer(const Candidate& c) {
    if (heap_.size() < k_) {
      heap_.push_back(c);
      std::push_heap(heap_.begin(), heap_.end(), Before);
    } else if (Before(c, heap_.front())) {
      std::pop_heap(heap_.begin(), heap_.end(), Before);
      heap_.back() = c;
      std::push_heap(heap_.begin(), heap_.end(), Before);
    }
  }
  std::vector<Candidate>& items() { return heap_; }

 private:
  size_t k_;
  std::vector<Candidate> heap_;
};

// Blocks per task of the scan of every view (512 views): their codes (128 KB at 64 dimensions)
// and their inner products with a hand's 48 rolled queries (96 KB) stay in a core's L2.
constexpr size_t kScanBlocks = 64;

}  // namespace

std::vector<Candidate> ViewIndex::Candidates(std::span<const Point2f> query_px,
                                             const IndexSearchOptions& options,
                                             ThreadPool* pool) const {
  const int D = grid_.dims();
  const int d = dims_;
  const int threads = Threads(options.num_threads);
  const uint32_t rolls = num_rolls_;
  const size_t k = static_cast<size_t>(std::min<uint64_t>(
      static_cast<uint64_t>(std::max(1, options.candidates)), num_views_ * rolls));

  // Every rolled query as w_r = -V^T W^-1 u_r and offset_r = <u_r, mu>, so that
  // s(v, r) = offset_r - <w_r, z_v>: the query vectors u_r in parallel, then one product with the
  // projection and the mean (query_blocks_).
  std::vector<float> u(static_cast<size_t>(rolls) * static_cast<size_t>(D));
  auto rolled_vectors = [&](size_t r, int) {
    const std::vector<PointQ> rolled =
        RotateAndQuantise(query_px, -RollAngle(static_cast<roll_id_t>(r), rolls));
    QueryVector(grid_, rolled, weight_, u.data() + r * D);
    return true;
  };
  ParallelFor(rolls, threads, rolled_vectors, pool);
  const size_t query_rows = query_blocks_.size() / static_cast<size_t>(D);
  std::vector<float> projected(static_cast<size_t>(rolls) * query_rows);
  CodeInnerProducts(u.data(),
                    static_cast<int>(rolls),
                    query_blocks_.data(),
                    query_rows / kCodeLanes,
                    D,
                    projected.data());
  std::vector<float> w(static_cast<size_t>(rolls) * d);
  std::vector<double> offset(rolls);
  for (size_t r = 0; r < rolls; ++r) {
    const float* row = projected.data() + r * query_rows;
    for (int c = 0; c < d; ++c) w[r * d + c] = -row[c];
    offset[r] = row[d];
  }

  // Each worker keeps its own best k; their union holds the best k overall.
  std::vector<TopCandidates> best(static_cast<size_t>(threads), TopCandidates(k));
  // Offers the slots [slot0, slot0 + count) of the inner products ip[q * stride + i] of the
  // rolled queries `qs`.
  auto offer = [&](TopCandidates* top,
                   std::span<const uint32_t> qs,
                   const float* ip,
                   size_t stride,
                   size_t slot0,
                   size_t count) {
    for (size_t qi = 0; qi < qs.size(); ++qi) {
      const uint32_t r = qs[qi];
      const float* row = ip + qi * stride;
      // Floor() is conservative by far more than float rounding: a value below the float floor
      // is below the double one.
      float floor = static_cast<float>(top->Floor(offset[r]));
      for (size_t i = NextAtLeast(row, 0, count, floor); i < count;
           i = NextAtLeast(row, i + 1, count, floor)) {
        const view_id_t v = ids_[slot0 + i];
        if (v == kInvalidViewId) continue;
        top->Offer({v,
                    static_cast<roll_id_t>(r),
                    static_cast<float>(offset[r] - static_cast<double>(row[i]))});
        floor = static_cast<float>(top->Floor(offset[r]));
      }
    }
  };

  const int nprobe = std::min(options.nprobe, nlist_);
  const size_t lane = kCodeLanes;
  const size_t block_floats = static_cast<size_t>(d) * lane;
  if (nprobe <= 0) {
    // Every view against every rolled query, a task per kScanBlocks blocks.
    std::vector<uint32_t> all_rolls(rolls);
    for (uint32_t r = 0; r < rolls; ++r) all_rolls[r] = r;
    const size_t blocks = ids_.size() / lane;
    const size_t tasks = (blocks + kScanBlocks - 1) / kScanBlocks;
    std::vector<std::vector<float>> scratch(static_cast<size_t>(threads));
    auto scan_blocks = [&](size_t t, int worker) {
      const size_t b0 = t * kScanBlocks;
      const size_t nb = std::min(kScanBlocks, blocks - b0);
      std::vector<float>& ip = scratch[static_cast<size_t>(worker)];
      ip.resize(static_cast<size_t>(rolls) * nb * lane);
      CodeInnerProducts(
          w.data(), static_cast<int>(rolls), codes_.data() + b0 * block_floats, nb, d, ip.data());
      offer(&best[static_cast<size_t>(worker)],
            all_rolls,
            ip.data(),
            nb * lane,
            b0 * lane,
            nb * lane);
      return true;
    };
    ParallelFor(tasks, threads, scan_blocks, pool);
  } else {
    // IVF: per rolled query, the nprobe lists of largest <centroid, w_r> (= smallest s at the
    // centroid; ties: lower list), scanned in list order.
    std::vector<std::vector<float>> scratch(static_cast<size_t>(threads));
    auto probe_rolls = [&](size_t r, int worker) {
      const float* wr = w.data() + r * d;
      std::vector<std::pair<float, uint32_t>> lists(static_cast<size_t>(nlist_));
      for (size_t l = 0; l < lists.size(); ++l) {
        const float* c = centroids_.data() + l * d;
        double s = 0;
        for (int j = 0; j < d; ++j) s += static_cast<double>(wr[j]) * c[j];
        lists[l] = {static_cast<float>(s), static_cast<uint32_t>(l)};
      }
      std::partial_sort(
          lists.begin(), lists.begin() + nprobe, lists.end(), [](const auto& x, const auto& y) {
            return x.first != y.first ? x.first > y.first : x.second < y.second;
          });
      std::sort(lists.begin(), lists.begin() + nprobe, [](const auto& x, const auto& y) {
        return x.second < y.second;
      });
      const uint32_t qs[1] = {static_cast<uint32_t>(r)};
      std::vector<float>& ip = scratch[static_cast<size_t>(worker)];
      for (int p = 0; p < nprobe; ++p) {
        const size_t l = lists[static_cast<size_t>(p)].second;
        const size_t nb = (list_sizes_[l] + lane - 1) / lane;
        if (nb == 0) continue;
        ip.resize(nb * lane);
        CodeInnerProducts(
            wr, 1, codes_.data() + (list_begin_[l] / lane) * block_floats, nb, d, ip.data());
        offer(&best[static_cast<size_t>(worker)],
              qs,
              ip.data(),
              nb * lane,
              list_begin_[l],
              list_sizes_[l]);
      }
      return true;
    };
    ParallelFor(rolls, threads, probe_rolls, pool);
  }

  std::vector<Candidate> all;
  for (TopCandidates& t : best) all.insert(all.end(), t.items().begin(), t.items().end());
  const size_t keep = std::min(all.size(), k);
  std::partial_sort(all.begin(),
                    all.begin() + static_cast<std::ptrdiff_t>(keep),
                    all.end(),
                    TopCandidates::Before);
  all.resize(keep);
  return all;
}

}  // namespace handdb
