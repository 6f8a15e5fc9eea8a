// An index over a database's canonical views for search that does not touch every (view, roll)
// pair (docs/index.md): filter, then refine exactly.
//
// Filter. Each view's embedding e(Y_v) (query/index/embedding.h: an approximate chamfer distance
// as an inner product <u(Q_r), e(Y_v)>) is projected to `dims` dimensions by a PCA in the space
// whitened by the second moment of query vectors (the database's own views, rolled and mirrored):
// z_v = V^T W (e_v - mu) with W = E[u u^T]^(1/2), which keeps the inner products with likely
// queries rather than the vectors themselves (docs/index.md: recall of the two, measured). For a
// query, every roll r gives u_r = u(Q_r) and the score s(v, r) = <u_r, mu> + <V^T W^-1 u_r, z_v>.
// The best pairs by s come from a scan of every z_v with all rolled queries at once (a small
// matrix product, query/index/code_scan.h), or, with nprobe > 0, from an IVF probe: the views
// are in k-means lists (FAISS's k-means in L2), and each rolled query scans the nprobe lists
// whose centroids have the largest inner product with it.
// Refine. Query::Searcher computes the exact D_c of the candidates only (the same bounds, abandon
// rules and total order as exact search): the result is the exact top-k among the candidates,
// equal to exact search whenever the true top-k are candidates (recall, measured in bench/).
//
// The file (DB_DIR/index.hdbi, listed in the manifest) is versioned and checksummed; it records
// the database's fingerprint, so an index of other shards is refused (docs/index.md).
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/manifest.h"
#include "format/roll.h"
#include "format/view.h"
#include "query/index/embedding.h"

namespace handdb {

class Database;
class ThreadPool;

constexpr char kIndexFileName[] = "index.hdbi";
constexpr char kIndexKind[] = "chamfer-wpca-ivf";

struct IndexBuildOptions {
  int dims = 64;           // PCA dimensions (1 .. grid.dims())
  int nlist = 0;           // IVF lists; 0: 4 sqrt(views), within [1, views]
  int train_views = 4096;  // views sampled (evenly) for the PCA and the k-means
  EmbeddingGrid grid;      // 31 x 31 cells of 8 px (+-124 px)
  int num_threads = -1;    // -1: all cores
  bool progress = false;   // progress lines on stderr
  bool Check(std::string* error) const;
};

struct IndexSearchOptions {
  int candidates = 1000;  // (view, roll) pairs handed to the exact refine, per hand searched
  int nprobe = 0;         // IVF lists searched per rolled query; 0: every view, batched
  int num_threads = -1;
};

struct Candidate {
  view_id_t view = kInvalidViewId;
  roll_id_t roll = 0;
  float score = 0;  // the approximate coarse bound s(v, r), px
};

// A database's identity for its index: XXH3-64 over the roll count and each shard's file name,
// view count and whole-file checksum, in manifest order.
uint64_t DatabaseFingerprint(const Manifest& manifest);

class ViewIndex {
 public:
  ~ViewIndex();
  ViewIndex(ViewIndex&&) noexcept;
  ViewIndex& operator=(ViewIndex&&) noexcept;

  // Deterministic: the same database and options give the same bytes (Serialize).
  static Result<ViewIndex> Build(const Database& db, const IndexBuildOptions& options);

  // The file's bytes (docs/index.md, "File layout").
  std::string Serialize() const;
  // Parses and checks a file's bytes against the database it indexes: magic, version, sizes,
  // checksums, the database fingerprint and view/roll counts. `what` names the file in errors.
  static Result<ViewIndex> Parse(std::string_view bytes,
                                 uint64_t database_fingerprint,
                                 uint64_t num_views,
                                 uint32_t num_rolls,
                                 const std::string& what);
  // Reads DB_DIR's index as listed by the manifest (size and checksum checked), or kNotFound when
  // the manifest lists none.
  static Result<ViewIndex> Open(const std::filesystem::path& db_dir, const Manifest& manifest);

  // The best `options.candidates` pairs by approximate bound, best first (ties: view, roll), for
  // a query in the normalised frame (px), as searched (no mirroring here). On options.num_threads
  // workers, from `pool` when given (then at most its threads and the caller).
  std::vector<Candidate> Candidates(std::span<const Point2f> query_px,
                                    const IndexSearchOptions& options,
                                    ThreadPool* pool = nullptr) const;

  int dims() const { return dims_; }
  const EmbeddingGrid& grid() const { return grid_; }
  int nlist() const { return nlist_; }
  uint64_t num_views() const { return num_views_; }
  uint32_t num_rolls() const { return num_rolls_; }
  uint64_t fingerprint() const { return fingerprint_; }
  double build_seconds() const { return build_seconds_; }

 private:
  ViewIndex();
  int dims_ = 0;
  int nlist_ = 0;
  uint64_t num_views_ = 0;
  uint32_t num_rolls_ = 1;
  uint64_t fingerprint_ = 0;
  EmbeddingGrid grid_;
  float weight_ = 1;                     // w of query/index/embedding.h
  std::vector<float> mean_;              // grid.dims()
  std::vector<float> query_projection_;  // dims x grid.dims(), row-major: V^T W^-1
  // The lists, laid out for CodeInnerProducts: list l's views fill the slots [list_begin_[l],
  // list_begin_[l] + list_sizes_[l]) of ids_ (in increasing view id), padded with
  // kInvalidViewId to a multiple of kCodeLanes; codes_ holds the slots' z in blocks of
  // kCodeLanes (padding zero).
  std::vector<float> centroids_;  // nlist x dims
  std::vector<uint32_t> list_sizes_;
  std::vector<size_t> list_begin_;
  std::vector<view_id_t> ids_;
  std::vector<float> codes_;
  // query_projection_'s d rows and mean_ as one more row, in blocks of kCodeLanes rows.
  std::vector<float> query_blocks_;
  // Lays out the lists from the file's order (sizes per list, then ids and codes list by list)
  // and query_blocks_ from mean_ and query_projection_, which must be set.
  void SetLists(std::vector<float> centroids,
                std::vector<uint32_t> sizes,
                const std::vector<uint32_t>& ids,
                const float* codes);
  double build_seconds_ = 0;
};

}  // namespace handdb
