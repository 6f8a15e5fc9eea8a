// Exact top-k chamfer search over a database of virtual views (docs/query.md).
//
// Distance: D_c = A + B of query/chamfer.h, exact on the 1/16 px grid. Pruned search over the
// (view, slot) pairs, a slot being a (hand, roll): the query (mirrored for a left hand) rolled
// into the canonical frame:
//  1. Lower bounds L = L_A + L_B <= D_c: L_A of every pair from the views' coarse fields
//     (query/coarse_bound.h, one streaming product per slot), the threshold seeded by scoring
//     the pairs with the smallest L_A, then L_B (query/distance_transform.h, one distance grid
//     shared by up to four slots) for the pairs whose L_A is still below the k-th best D_c.
//  2. Visit pairs in increasing L; compute the exact A (linear scans, abandoned on a running
//     lower bound) and B only while L <= the current k-th best D_c.
// The result is exactly the top-k of brute force under the total order (D_c, view id, roll,
// right before left), identical for any thread count and either kd-tree backend.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "format/roll.h"
#include "format/view.h"
#include "query/coarse_bound.h"
#include "query/database.h"
#include "query/index/view_index.h"
#include "query/kdtree.h"

namespace handdb {

// Which hand the query shows. The database is a right hand; a left hand is its mirror image, and
// mirroring the query's normalised points (x -> -x, exact in float and on the PointQ grid) matches
// it against the right-hand views exactly (docs/query.md, "Either hand").
enum class Hand { kRight, kLeft, kEither };
std::string_view HandName(Hand hand);  // "right", "left", "either"
Result<Hand> ParseHand(std::string_view name);

// kExact: every (view, slot) pair is bounded, the exact top-k. kIndexed: the database's index
// (query/index/view_index.h, docs/index.md) gives candidate (view, roll) pairs per hand searched
// (the left hand's from the mirrored query), and only those pairs of the hand's slots are bounded
// and refined, by the same steps: the exact top-k among the candidates. kAuto: kIndexed when the
// Searcher has an index attached (SearcherOptions::use_index), else kExact.
enum class SearchMode { kAuto, kExact, kIndexed };
std::string_view SearchModeName(SearchMode mode);  // "auto", "exact", "indexed"

// Whether a Searcher attaches its database's index when it opens: kAuto when the manifest lists
// one, kIndexed always (an error without one), kExact never.
enum class IndexUse { kAuto, kExact, kIndexed };
std::string_view IndexUseName(IndexUse use);  // "auto", "exact", "indexed"
Result<IndexUse> ParseIndexUse(std::string_view name);

struct SearcherOptions {
  // The Searcher's one thread pool, started at open and used by every phase (opening, the lazy
  // caches, every search). -1: all cores; at most MaxNumThreads() (base/thread_pool.h).
  int num_threads = -1;
  bool verify = false;  // Open: hash every shard section (Database::Open)
  IndexUse use_index = IndexUse::kAuto;
  // A process that runs one or a few queries: exact searches bound A with the shards' stored box
  // fields when every shard has them (SetExactFieldKind(kBox): ~0.1 s to prepare against ~0.7 s
  // for the centre fields, more than one query gains; the results are the same).
  bool few_queries = false;
  bool Check() const;
};

// One (view, roll, hand) of a restricted search (SearchOptions::subset); hand is kRight or kLeft.
struct SearchPair {
  view_id_t view = kInvalidViewId;
  roll_id_t roll = 0;
  Hand hand = Hand::kRight;
};

struct SearchOptions {
  int top_k = 10;  // number of matches returned
  // At most this many matches per basic shape (0: no limit). 1 ranks shapes: the top k are the k
  // shapes with the nearest views, each by its best (view, roll, hand), which is what "the top 5
  // shapes" means to a user who wants a shape, not five rolls of one view (docs/query.md, "One
  // match per shape"). The result is exactly the brute-force top k under the limit; views
  // without a shape id count as one shape.
  int max_per_shape = 0;
  // kRight: today's search. kLeft: the query is mirrored before searching. kEither: both, in one
  // search with one top-k ordered by (D_c, view id, roll, right before left), which is exactly
  // the merge of the two hands' results; the mirrored rolls share the right hand's distance
  // grids. The library default stays kRight (the rendered test sets are right hands);
  // `handdb query` defaults to kEither.
  Hand hand = Hand::kRight;
  // -1: every thread of the Searcher's pool; fewer caps this search (never more than the pool).
  int num_threads = -1;
  bool brute_force = false;  // D_c for every (view, roll), no pruning (the reference)
  KdTreeBackend kdtree = KdTreeBackend::kNanoflann;
  float dt_cell_px = 1.0f;  // distance-transform grid step: 1, 1/2, 1/4, 1/8 or 1/16 px
  // Also bound the query -> view term A from the views' coarse fields (query/coarse_field.h)
  // before any kd-tree. Off: the B bound alone (for comparison; results are identical).
  bool coarse_bound = true;
  // A progress line on stderr (base/progress.h) per phase of a long search ("query bounds" over
  // rolls, "query refine" / "query brute force" over (view, roll) pairs, per hand searched), but
  // only once the work has run 1 s on a terminal or 5 s otherwise, counted from progress_since
  // (default: the start of Search); a fast search prints nothing (Progress::QuietUnlessSlow).
  // `handdb query` turns it on (off with --quiet) from the command's start; `--top 100000`,
  // `--bruteforce` and big photo queries otherwise ran for minutes without a sign of life.
  bool progress = false;
  std::chrono::steady_clock::time_point progress_since{};
  // kIndexed needs an index (attached at open, or Searcher::SetIndex); `index` says how many
  // candidates per hand. kAuto follows the Searcher: indexed when it has an index.
  SearchMode mode = SearchMode::kAuto;
  IndexSearchOptions index;
  // Not empty: the search is restricted to these pairs (a tracker's neighbourhood of the last
  // answer), bounded and refined as kIndexed's candidates are: the exact top-k of brute force
  // over the subset, whatever `mode` says (brute_force ignores it: every pair). Pairs of a hand not
  // searched (`hand`) or outside the database are ignored; repeats are allowed. The caller keeps
  // the pairs alive during Search.
  std::span<const SearchPair> subset;
  bool Check() const;
};

struct Match {
  view_id_t view_id = kInvalidViewId;
  roll_id_t roll = 0;
  float roll_angle = 0;    // radians, 2*pi*roll/R
  double distance = 0;     // D_c = a + b, px
  double a = 0;            // query -> view term, px
  double b = 0;            // view -> query term, px
  double lower_bound = 0;  // the bound L(v, r) <= D_c used for pruning (the B bound, plus the
                           // coarse A bound), rounded down to 1/64 px (0 in brute force)
  ViewLabel label;         // rolled: camera_roll += angle, keypoints rotated (RollLabel)
  std::string shape_name;  // from the database's shape table, "" if unknown
  // kRight, or kLeft when the mirrored query matched: then `label` is mirrored back into the
  // query's frame (MirrorLabel), so keypoints are where the left hand's joints are.
  Hand hand = Hand::kRight;
  // Re-ranked by a photo's hand landmarks (pose/landmark_rank.h): the mean distance of the
  // keypoints to the landmarks (in hand radii: normalised px / 96) and the score the matches
  // are ranked by, distance / (the pool's best distance) + weight * landmark_error.
  // -1: ranked by D_c alone.
  double landmark_error = -1;
  double score = -1;
};

// A right-hand view's label as the left hand seen in the mirrored picture: keypoint x -> -x
// (the normalised frame's origin is on the mirror line), camera_roll -> -camera_roll (the mirror
// turns rotations round); joint angles are unchanged (the same flexions of a left hand). The view
// direction is expressed in the left hand's frame, defined as the right hand's frame with y
// negated (for the WebXR hand y is the lateral axis: forward_axis -z and palm_normal -x stay),
// so view_direction.y and view_phi change sign and view_theta stays. Its own inverse.
ViewLabel MirrorLabel(const ViewLabel& label);

struct SearchStats {
  uint64_t virtual_views = 0;    // (view, roll) pairs in the database
  uint64_t bounded = 0;          // pairs whose lower bound was computed (both hands: 2 per pair)
  uint64_t grids = 0;            // distance grids built (query/distance_transform.h)
  uint64_t grid_bounded = 0;     // pairs whose B bound was computed from a grid
  uint64_t refined = 0;          // pairs whose exact D_c was started
  uint64_t abandoned = 0;        // of those, stopped early above the k-th best
  uint64_t probe_abandoned = 0;  // of those, dropped by the linear scans' running bound
  uint64_t view_trees = 0;       // kd-trees built over view points
  uint64_t query_points = 0;
  uint32_t searches = 0;                 // hands searched: 1, or 2 for Hand::kEither
  SearchMode mode = SearchMode::kExact;  // what the search ran: kExact or kIndexed
  // kIndexed: pairs the index proposed (the only ones bounded); a subset search (reported as
  // kExact): the subset's pairs searched.
  uint64_t candidates = 0;
  double seconds_index = 0;   // kIndexed: the index's candidate search
  double seconds_bounds = 0;  // step 1 (rotations, coarse bounds, distance transforms, B bounds)
  double seconds_refine = 0;  // step 2
  double seconds_total = 0;
};

class ThreadPool;

class Searcher {
 public:
  // The database is shared (a Searcher is cheap; many may search one Database). Starts the pool
  // of options.num_threads (throws std::system_error when the system refuses a thread: Create
  // and Open return that as a Status); attaches no index (see Create).
  explicit Searcher(std::shared_ptr<const Database> db, const SearcherOptions& options = {});
  ~Searcher();
  Searcher(const Searcher&) = delete;
  Searcher& operator=(const Searcher&) = delete;

  // Opens a database directory (Database::Open, on the Searcher's pool) and wraps it as Create
  // does: every caller that opens a database this way searches it the same way.
  static Result<std::unique_ptr<Searcher>> Open(const std::filesystem::path& dir,
                                                const SearcherOptions& options = {});
  // Wraps an open database: checks the options, starts the pool, and attaches the index its
  // manifest lists (ViewIndex::Open) as options.use_index says.
  static Result<std::unique_ptr<Searcher>> Create(std::shared_ptr<const Database> db,
                                                  const SearcherOptions& options = {});

  // Top-k matches for a query edge point set in the normalised frame (px), best first.
  // kInvalidArgument for an empty query or bad options. Const: safe from many threads.
  Result<std::vector<Match>> Search(std::span<const Point2f> query_px,
                                    const SearchOptions& options,
                                    SearchStats* stats = nullptr) const;

  const Database& database() const { return *db_; }

  // Builds now what exact searches build on first use: every view's coarse field, cell-major
  // (CoarseFields of SetExactFieldKind's kind: centre fields ~0.7 s on 2 threads, box fields
  // ~0.1 s, 41 MB either way for 1M virtual views) and the views' cell histograms. For benchmarks
  // and servers that should not pay it in their first query; a process that runs indexed searches
  // only never needs it (they read the shards' box fields).
  void PrepareExactSearch() const;

  // Which coarse field the exact search bounds A with (docs/query.md "The centre field"):
  // kCentre, the default, computed from the points when first needed (~60 us per view) and
  // tighter; or kBox, the shards' own fields, copied (fast to prepare: what a process that runs
  // a single query on a database with stored fields should use, `handdb query`). The results
  // are the same. Call before the first exact search (later calls have no effect).
  void SetExactFieldKind(FieldKind kind) { exact_field_kind_ = kind; }

  // The index kIndexed searches use (built for this database: ViewIndex::Open checks that).
  void SetIndex(std::shared_ptr<const ViewIndex> index) { index_ = std::move(index); }
  const ViewIndex* index() const { return index_.get(); }

  // What a search with these options runs: kExact or kIndexed (kAuto resolved by index(); brute
  // force is exact).
  SearchMode ModeFor(const SearchOptions& options) const;
  // The threads a search may use: the pool's plus the calling thread.
  int num_threads() const { return num_threads_; }

 private:
  Searcher(std::shared_ptr<const Database> db,
           const SearcherOptions& options,
           std::unique_ptr<ThreadPool> pool);
  // Attaches the index the options ask for to a new Searcher over `db` and `pool`.
  static Result<std::unique_ptr<Searcher>> Make(std::shared_ptr<const Database> db,
                                                const SearcherOptions& options,
                                                std::unique_ptr<ThreadPool> pool);
  Result<std::vector<Match>> SearchImpl(std::span<const Point2f> query_px,
                                        const SearchOptions& options,
                                        SearchStats* stats) const;
  std::shared_ptr<const Database> db_;
  // num_threads_ - 1 workers (none for one thread): the calling thread is always worker 0.
  int num_threads_ = 1;
  std::unique_ptr<ThreadPool> pool_;
  std::vector<int32_t> max_abs_;  // per view: max |x|, |y| of its points (PointQ units)
  // Per view: 1 if its points are sorted by y and on the coarse grid (every converted view), so
  // the linear scans may read a window of rows (docs/query.md).
  std::vector<uint8_t> y_sorted_;
  // Half extent of the per-roll distance grids: the largest |x|, |y| of any view (px), so every
  // view's points are on the grid (the fast path) and no node is computed that no view reads.
  float grid_half_extent_px_ = 0;
  // Per view: the A bound's field (centre, or box: exact_field_kind_), laid out cell-major by
  // the first exact search (cell_major_fields()); indexed searches read the shards' own
  // row-major box fields (coarse_rows_, when every shard has them).
  const CoarseFields& cell_major_fields() const;
  FieldKind exact_field_kind_ = FieldKind::kCentre;
  mutable std::once_flag cell_major_once_;
  mutable CoarseFields cell_major_;
  CoarseFields coarse_rows_;
  // Per view: its points per coarse cell (the coarse B bound), built by the first exact pruned
  // search (indexed and brute-force searches never read them).
  const ViewHistograms& view_histograms() const;
  mutable std::once_flag view_histograms_once_;
  mutable ViewHistograms view_histograms_;
  // Per view: its shape as a dense index (the distinct shape ids in increasing order, views
  // without one as the last), built by the first search with a per-shape limit.
  struct ShapeIndex {
    std::vector<uint32_t> of_view;
    size_t num_shapes = 0;
  };
  const ShapeIndex& shape_index() const;
  mutable std::once_flag shape_index_once_;
  mutable ShapeIndex shape_index_;
  std::shared_ptr<const ViewIndex> index_;
};

}  // namespace handdb
