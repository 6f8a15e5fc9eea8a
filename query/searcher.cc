#include "query/searcher.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>

#include "base/progress.h"
#include "base/thread_pool.h"
#include "query/coarse_bound.h"
#include "query/search_run.h"

namespace handdb {

using search_internal::SearchInputs;
using search_internal::SearchRun;

bool SearchOptions::Check() const {
  CHECK_OPTION_GT(top_k, 0);
  CHECK_OPTION_GE(max_per_shape, 0);
  CHECK_OPTION(num_threads == -1 || (num_threads >= 1 && num_threads <= MaxNumThreads()));
  CHECK_OPTION((DistanceGridOptions{dt_cell_px, 170.0f}.Check()));
  CHECK_OPTION_GT(index.candidates, 0);
  CHECK_OPTION(index.nprobe >= 0);
  return true;
}

bool SearcherOptions::Check() const {
  CHECK_OPTION(num_threads == -1 || (num_threads >= 1 && num_threads <= MaxNumThreads()));
  return true;
}

namespace {

// The pool of a Searcher with `num_threads` threads: the calling thread is worker 0, so one
// fewer in the pool, and none for one thread (a search then starts no thread at all).
std::unique_ptr<ThreadPool> StartPool(int num_threads) {
  const int threads = ResolveNumThreads(num_threads);
  return threads > 1 ? std::make_unique<ThreadPool>(threads - 1) : nullptr;
}

}  // namespace

Searcher::Searcher(std::shared_ptr<const Database> db, const SearcherOptions& options)
    : Searcher(std::move(db), options, StartPool(options.num_threads)) {}

Searcher::Searcher(std::shared_ptr<const Database> db,
                   const SearcherOptions& options,
                   std::unique_ptr<ThreadPool> pool)
    : db_(std::move(db)),
      num_threads_(pool != nullptr ? pool->NumThreads() + 1 : 1),
      pool_(std::move(pool)) {
  THROW_CHECK(db_ != nullptr);
  THROW_CHECK(options.Check());
  if (options.few_queries && db_->has_coarse_fields()) exact_field_kind_ = FieldKind::kBox;
  max_abs_.resize(db_->num_views());
  y_sorted_.resize(db_->num_views());
  // Every view's extent and order: read from its points once here, in parallel (on a
  // 10M-virtual-view database ~0.5 GB of mapped points), or from the summaries a database with
  // coded shards made at open.
  constexpr size_t kChunk = 4096;
  const auto& summaries = db_->point_summaries();
  auto summarise = [&](size_t k, int) {
    const size_t end = std::min<size_t>(db_->num_views(), (k + 1) * kChunk);
    for (size_t v = k * kChunk; v < end; ++v) {
      const Database::PointSummary sum =
          db_->coded() ? summaries[v] : Database::Summarise(db_->points(static_cast<view_id_t>(v)));
      max_abs_[v] = sum.max_abs;
      y_sorted_[v] = sum.max_abs < CoarseGrid::kHalfUnits && sum.sorted_by_y;
    }
    return true;
  };
  ParallelFor((db_->num_views() + kChunk - 1) / kChunk, num_threads_, summarise, pool_.get());
  // The grid holds distances to the rolled query, looked up only at view points; its bounds
  // are the same at every node whatever the extent (it grows to contain the query), so the
  // smallest extent that keeps every view on the grid gives identical bounds at the least cost.
  // Views are normalised to lie within 166.3 px of the origin, in practice ~115 px: half the
  // nodes of the 170 px default (docs/query.md).
  const int32_t db_max_abs =
      max_abs_.empty() ? 0 : *std::max_element(max_abs_.begin(), max_abs_.end());
  grid_half_extent_px_ =
      std::clamp(static_cast<float>(db_max_abs) / kPointScale + 1.0f, 8.0f, 2000.0f);
  if (db_->has_coarse_fields()) coarse_rows_ = CoarseFields::RowMajor(*db_);
}

const CoarseFields& Searcher::cell_major_fields() const {
  std::call_once(cell_major_once_, [this] {
    cell_major_ = CoarseFields(*db_, num_threads_, exact_field_kind_, pool_.get());
  });
  return cell_major_;
}

void Searcher::PrepareExactSearch() const {
  cell_major_fields();
  view_histograms();
}

const ViewHistograms& Searcher::view_histograms() const {
  std::call_once(view_histograms_once_,
                 [this] { view_histograms_ = ViewHistograms(*db_, num_threads_, pool_.get()); });
  return view_histograms_;
}

const Searcher::ShapeIndex& Searcher::shape_index() const {
  std::call_once(shape_index_once_, [this] {
    const size_t n = db_->num_views();
    std::vector<shape_id_t> ids(n);
    constexpr size_t kChunk = 4096;
    auto read_shape_ids = [&](size_t c, int) {
      for (size_t v = c * kChunk; v < std::min(n, (c + 1) * kChunk); ++v) {
        ids[v] = db_->label(static_cast<view_id_t>(v)).shape_id;
      }
      return true;
    };
    ParallelFor((n + kChunk - 1) / kChunk, num_threads_, read_shape_ids, pool_.get());
    std::vector<shape_id_t> distinct = ids;
    std::sort(distinct.begin(), distinct.end());
    distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
    shape_index_.of_view.resize(n);
    for (size_t v = 0; v < n; ++v) {
      shape_index_.of_view[v] = static_cast<uint32_t>(
          std::lower_bound(distinct.begin(), distinct.end(), ids[v]) - distinct.begin());
    }
    shape_index_.num_shapes = distinct.size();
  });
  return shape_index_;
}

Searcher::~Searcher() = default;

namespace {

Status CheckSearcherOptions(const SearcherOptions& options) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument,
                  "threads " + std::to_string(options.num_threads) + ": must be -1 or 1.." +
                      std::to_string(MaxNumThreads()) + " (4x the cores, at most 256)");
  }
  return Status::Ok();
}

// The index the options ask for, or null: kAuto attaches the manifest's, kIndexed needs one.
Result<std::shared_ptr<const ViewIndex>> OpenIndex(const Database& db,
                                                   const SearcherOptions& options) {
  if (options.use_index == IndexUse::kExact) return std::shared_ptr<const ViewIndex>();
  if (options.use_index == IndexUse::kAuto && !db.manifest().index) {
    return std::shared_ptr<const ViewIndex>();
  }
  Result<ViewIndex> index = ViewIndex::Open(db.path(), db.manifest());
  if (!index.ok()) return index.status();
  return std::make_shared<const ViewIndex>(std::move(index).value());
}

// The Searcher's pool (none for one thread), or the error of a thread the system refused.
Result<std::unique_ptr<ThreadPool>> CreatePool(int num_threads) {
  const int threads = ResolveNumThreads(num_threads);
  if (threads <= 1) return std::unique_ptr<ThreadPool>();
  return ThreadPool::Create(threads - 1);
}

}  // namespace

Result<std::unique_ptr<Searcher>> Searcher::Open(const std::filesystem::path& dir,
                                                 const SearcherOptions& options) {
  HANDDB_RETURN_IF_ERROR(CheckSearcherOptions(options));
  Result<std::unique_ptr<ThreadPool>> pool = CreatePool(options.num_threads);
  if (!pool.ok()) return pool.status();
  Result<Database> db = Database::Open(
      dir, options.verify, ResolveNumThreads(options.num_threads), pool.value().get());
  if (!db.ok()) return db.status();
  return Make(
      std::make_shared<const Database>(std::move(db).value()), options, std::move(pool).value());
}

Result<std::unique_ptr<Searcher>> Searcher::Create(std::shared_ptr<const Database> db,
                                                   const SearcherOptions& options) {
  THROW_CHECK(db != nullptr);
  HANDDB_RETURN_IF_ERROR(CheckSearcherOptions(options));
  Result<std::unique_ptr<ThreadPool>> pool = CreatePool(options.num_threads);
  if (!pool.ok()) return pool.status();
  return Make(std::move(db), options, std::move(pool).value());
}

Result<std::unique_ptr<Searcher>> Searcher::Make(std::shared_ptr<const Database> db,
                                                 const SearcherOptions& options,
                                                 std::unique_ptr<ThreadPool> pool) {
  Result<std::shared_ptr<const ViewIndex>> index = OpenIndex(*db, options);
  if (!index.ok()) return index.status();
  std::unique_ptr<Searcher> searcher(new Searcher(std::move(db), options, std::move(pool)));
  searcher->SetIndex(std::move(index).value());
  return searcher;
}

SearchMode Searcher::ModeFor(const SearchOptions& options) const {
  if (options.brute_force) return SearchMode::kExact;
  if (options.mode == SearchMode::kAuto) {
    return index_ != nullptr ? SearchMode::kIndexed : SearchMode::kExact;
  }
  return options.mode;
}

namespace {

// The index's candidates per hand searched (the left hand's from the mirrored query), as pairs
// (s * num_views + v) of the run's slots: the left hand's rolls follow the right hand's in a
// both-hand run. Adds the candidates proposed to *proposed.
std::vector<uint32_t> CandidatePairs(const ViewIndex& index,
                                     const Database& db,
                                     std::span<const Point2f> query_px,
                                     const SearchOptions& options,
                                     int threads,
                                     ThreadPool* pool,
                                     uint64_t* proposed) {
  IndexSearchOptions index_options = options.index;
  index_options.num_threads = threads;
  std::vector<uint32_t> pairs;
  size_t first_slot = 0;
  for (Hand h : {Hand::kRight, Hand::kLeft}) {
    if (options.hand != Hand::kEither && options.hand != h) continue;
    std::vector<Point2f> mirrored;
    if (h == Hand::kLeft) {
      mirrored.assign(query_px.begin(), query_px.end());
      for (Point2f& p : mirrored) p.x = -p.x;
    }
    const std::vector<Candidate> candidates = index.Candidates(
        h == Hand::kLeft ? std::span<const Point2f>(mirrored) : query_px, index_options, pool);
    *proposed += candidates.size();
    for (const Candidate& c : candidates) {
      if (c.view >= db.num_views() || c.roll >= db.num_rolls()) continue;
      pairs.push_back(static_cast<uint32_t>((first_slot + c.roll) * db.num_views() + c.view));
    }
    first_slot += db.num_rolls();
  }
  return pairs;
}

// SearchOptions::subset as pairs (s * num_views + v) of the run's slots, as CandidatePairs.
std::vector<uint32_t> SubsetPairs(const Database& db, const SearchOptions& options) {
  std::vector<uint32_t> pairs;
  pairs.reserve(options.subset.size());
  const bool both = options.hand == Hand::kEither;
  for (const SearchPair& p : options.subset) {
    if (p.view >= db.num_views() || p.roll >= db.num_rolls()) continue;
    if (p.hand != Hand::kRight && p.hand != Hand::kLeft) continue;
    if (!both && p.hand != options.hand) continue;
    const size_t first_slot = both && p.hand == Hand::kLeft ? db.num_rolls() : 0;
    pairs.push_back(static_cast<uint32_t>((first_slot + p.roll) * db.num_views() + p.view));
  }
  return pairs;
}

// An indexed search needs an index of this database.
Status CheckIndex(const ViewIndex* index, const Database& db) {
  if (index == nullptr) {
    return Status(StatusCode::kInvalidArgument,
                  db.path().string() + ": indexed search needs an index (build one: handdb index " +
                      db.path().string() + ")");
  }
  if (index->num_views() != db.num_views() || index->num_rolls() != db.num_rolls()) {
    return Status(StatusCode::kSizeMismatch,
                  db.path().string() + ": the index is of another database");
  }
  return Status::Ok();
}

// The query points must be finite and inside the normalised frame.
Status CheckQuery(std::span<const Point2f> query_px, const SearchOptions& options) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "invalid search options (see the line above)");
  }
  if (query_px.empty()) {
    return Status(StatusCode::kInvalidArgument, "the query has no edge points");
  }
  for (const Point2f& p : query_px) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || std::fabs(p.x) > 2000.0f ||
        std::fabs(p.y) > 2000.0f) {
      return Status(StatusCode::kInvalidArgument,
                    "query point (" + std::to_string(p.x) + ", " + std::to_string(p.y) +
                        ") is not finite or outside +-2000 px of the normalised frame");
    }
  }
  return Status::Ok();
}

}  // namespace

std::string_view SearchModeName(SearchMode mode) {
  switch (mode) {
    case SearchMode::kAuto:
      return "auto";
    case SearchMode::kExact:
      return "exact";
    case SearchMode::kIndexed:
      return "indexed";
  }
  return "?";
}

std::string_view IndexUseName(IndexUse use) {
  switch (use) {
    case IndexUse::kAuto:
      return "auto";
    case IndexUse::kExact:
      return "exact";
    case IndexUse::kIndexed:
      return "indexed";
  }
  return "?";
}

Result<IndexUse> ParseIndexUse(std::string_view name) {
  for (IndexUse u : {IndexUse::kAuto, IndexUse::kExact, IndexUse::kIndexed}) {
    if (name == IndexUseName(u)) return u;
  }
  return Status(StatusCode::kInvalidArgument,
                "unknown search '" + std::string(name) + "' (auto, exact or indexed)");
}

std::string_view HandName(Hand hand) {
  switch (hand) {
    case Hand::kRight:
      return "right";
    case Hand::kLeft:
      return "left";
    case Hand::kEither:
      return "either";
  }
  return "?";
}

Result<Hand> ParseHand(std::string_view name) {
  for (Hand h : {Hand::kRight, Hand::kLeft, Hand::kEither}) {
    if (name == HandName(h)) return h;
  }
  return Status(StatusCode::kInvalidArgument,
                "unknown hand '" + std::string(name) + "' (right, left or either)");
}

ViewLabel MirrorLabel(const ViewLabel& label) {
  ViewLabel out = label;
  for (auto& kp : out.keypoints) kp[0] = -kp[0];
  out.camera_roll = -label.camera_roll;
  out.view_direction[1] = -label.view_direction[1];
  out.view_phi = -label.view_phi;
  return out;
}

Result<std::vector<Match>> Searcher::Search(std::span<const Point2f> query_px,
                                            const SearchOptions& options,
                                            SearchStats* stats) const {
  try {
    return SearchImpl(query_px, options, stats);
  } catch (const CodedViewError& e) {
    // A coded view that does not decode (query/database.h): the search's error, not a crash.
    return Status(e.status().code(),
                  e.status().message() + " (run 'handdb validate " + db_->path().string() +
                      "' for every problem)");
  }
}

Result<std::vector<Match>> Searcher::SearchImpl(std::span<const Point2f> query_px,
                                                const SearchOptions& options,
                                                SearchStats* stats) const {
  const auto start = std::chrono::steady_clock::now();
  if (Status s = CheckQuery(query_px, options); !s.ok()) return s;
  const bool subset = !options.subset.empty() && !options.brute_force;
  const bool indexed = !subset && ModeFor(options) == SearchMode::kIndexed;
  if (indexed) HANDDB_RETURN_IF_ERROR(CheckIndex(index_.get(), *db_));

  // A coded database's views decoded for this search stay valid until it returns (the pin);
  // then the searches' cache is trimmed if it outgrew its budget (query/database.h).
  struct TrimAfter {
    const Database& db;
    ~TrimAfter() { db.TrimSearchCache(); }
  } trim_after{*db_};
  const Database::SearchPin pin(*db_);
  // The Searcher's pool, capped by the options; the calling thread is worker 0.
  const int threads = std::min(ResolveNumThreads(options.num_threads), num_threads_);
  ThreadPool* pool = threads > 1 ? pool_.get() : nullptr;
  const auto progress_since = options.progress_since == std::chrono::steady_clock::time_point{}
                                  ? start
                                  : options.progress_since;
  SearchStats local;
  local.virtual_views = db_->num_virtual_views();
  local.query_points = query_px.size();
  local.searches = options.hand == Hand::kEither ? 2 : 1;
  local.mode = indexed ? SearchMode::kIndexed : SearchMode::kExact;

  // The coarse fields the bounds read: none for brute force (it scores every pair with the
  // kd-trees), the shards' own for indexed search when they have them, else the cell-major copy.
  const CoarseFields* fields = nullptr;
  if (options.coarse_bound && !options.brute_force && db_->num_views() > 0) {
    fields = (indexed || subset) && !coarse_rows_.empty() ? &coarse_rows_ : &cell_major_fields();
  }
  const ShapeIndex* shapes = options.max_per_shape > 0 ? &shape_index() : nullptr;
  // Hand::kEither searches both hands' slots in one run with one top k, ordered by (D_c, view
  // id, roll, right before left): exactly the merge of the two brute-force searches.
  SearchInputs in;
  in.db = db_.get();
  in.max_abs = max_abs_;
  in.y_sorted = y_sorted_;
  in.grid_half_extent_px = grid_half_extent_px_;
  in.coarse = fields;
  in.view_histograms = fields != nullptr && !indexed && !subset ? &view_histograms() : nullptr;
  if (shapes != nullptr) {
    in.shape_of = shapes->of_view;
    in.num_shapes = shapes->num_shapes;
  }
  in.threads = threads;
  in.pool = pool;
  in.progress_since = progress_since;
  SearchRun run(in, query_px, options);
  if (options.brute_force) {
    run.BruteForce(&local, start);
  } else if (indexed || subset) {
    std::vector<uint32_t> pairs =
        subset ? SubsetPairs(*db_, options)
               : CandidatePairs(*index_, *db_, query_px, options, threads, pool, &local.candidates);
    if (subset) local.candidates = pairs.size();
    local.seconds_index = SecondsSince(start);
    const auto bounds_start = std::chrono::steady_clock::now();
    run.BoundCandidates(std::move(pairs));
    local.seconds_bounds = SecondsSince(bounds_start);
    const auto refine_start = std::chrono::steady_clock::now();
    run.Refine();
    local.seconds_refine = SecondsSince(refine_start);
  } else {
    run.Bounds();
    local.seconds_bounds = SecondsSince(start);
    const auto refine_start = std::chrono::steady_clock::now();
    run.Refine();
    local.seconds_refine = SecondsSince(refine_start);
  }
  run.AddInto(&local);
  std::vector<Match> matches = run.Matches();
  local.seconds_total = SecondsSince(start);
  if (stats != nullptr) *stats = local;
  return matches;
}

}  // namespace handdb
