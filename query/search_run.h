// One search's run over its slots' (view, slot) pairs (query/searcher.h): lower bounds, then
// the exact D_c of the pairs whose bound is at or below the k-th best, into the top k; or the
// brute-force reference. Internal to query/.
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "base/floor_divider.h"
#include "base/progress.h"
#include "query/coarse_bound.h"
#include "query/distance_transform.h"
#include "query/search_context.h"
#include "query/searcher.h"
#include "query/top_k.h"

namespace handdb {

class ThreadPool;

namespace search_internal {

// The slots of a search, the first hand's rolls first: right, left, or right then left.
std::vector<Slot> MakeSlots(Hand hand, uint32_t rolls);

// The slots that share one distance grid, the base (kNone) first. With R even, roll r + R/2 is
// roll r turned by 180 degrees (kXY). The left hand's roll r' is the right hand's roll R - r'
// mirrored in x: rot(-a) M X = M rot(a) X with M = diag(-1, 1), and a = -angle(R - r') (kX), and
// its roll R/2 - r is then the right roll r + R/2 mirrored, i.e. roll r reflected in y (kY). So a
// both-hand search needs R/2 grids for its 2R slots (docs/query.md); the coarse fields are
// copied along these groups.
std::vector<std::vector<GridMember>> MakeGridGroups(size_t num_slots, uint32_t rolls);

// The groups that share one distance grid in the fine bounds: with R a multiple of 4, group r
// and group r + R/4 (read turned) for r < R/4, so a both-hand search builds R/4 grids for its 2R
// slots; otherwise MakeGridGroups'.
std::vector<std::vector<GridMember>> MakeFineGridGroups(size_t num_slots, uint32_t rolls);

// What a run reads of its Searcher: the database, its per-view summaries, the fields and
// histograms the bounds read (null: none), each view's dense shape index (empty: no per-shape
// limit), and the workers (the calling thread and threads - 1 of `pool`).
struct SearchInputs {
  const Database* db = nullptr;
  std::span<const int32_t> max_abs;
  std::span<const uint8_t> y_sorted;
  float grid_half_extent_px = 0;
  const CoarseFields* coarse = nullptr;
  const ViewHistograms* view_histograms = nullptr;
  std::span<const uint32_t> shape_of;
  size_t num_shapes = 0;
  int threads = 1;
  ThreadPool* pool = nullptr;
  std::chrono::steady_clock::time_point progress_since;
};

// One query's stages, sharing the query context, the top k and the counters: BruteForce(), or
// Bounds() (indexed search: BoundCandidates()) then Refine(); then Matches(). Pairs are indexed
// s * num_views + v over the slots s.
class SearchRun {
 public:
  SearchRun(const SearchInputs& in,
            std::span<const Point2f> query_px,
            const SearchOptions& options);

  size_t num_slots() const { return ctx_.num_slots(); }

  // The reference: exact D_c for every (view, slot).
  void BruteForce(SearchStats* stats, std::chrono::steady_clock::time_point start);

  // Step 1: lower bounds of every pair, L = L_A + L_B (docs/query.md).
  //  a. Every slot's rolled query, coarse histogram and coarse field.
  //  b. The cell-only L_A of every pair: per block of views, one streaming product per slot
  //     (CoarseFields); and the coarse B bound L_Bc of the same views, one product per view for
  //     all slots (ViewHistograms), into lb_.
  //  c. The threshold seeded: the pairs with the smallest L_A + L_Bc scored exactly, so that it
  //     is near the final k-th best before any distance grid is built. Then L_A with the
  //     neighbour terms, only for the groups of 32 views that hold a pair still at or below it.
  //  d. Per grid group (up to four slots sharing one distance transform), most promising first:
  //     L_B for the pairs whose L_A + L_Bc is still <= the k-th best, stopped as soon as L_A +
  //     L_B exceeds it (lb_ keeps the larger of L_Bc and L_B), then each slot's best two pairs
  //     scored. A group with no such pair builds no grid.
  void Bounds();

  // Step 1 of indexed search (SearchMode::kIndexed): Bounds() over the candidate pairs only
  // (s * num_views + v, any order, repeats allowed), each an entry of la_ / lb_ in increasing
  // pair order: the slots of the grid groups holding candidates prepared, L_A per pair (the same
  // exact integer sum as the streaming product, so the same bound), the threshold seeded from
  // them, then L_B from the groups' grids (no L_Bc: measured no faster on a few thousand
  // candidates, docs/query.md). Refine() then gives the exact top-k among the candidates; with
  // every pair a candidate, exactly the result of Bounds() and Refine().
  void BoundCandidates(std::vector<uint32_t> pairs);

  // Step 2: visit pairs in increasing bound. First the k smallest bounds give a threshold,
  // then only pairs whose bound is <= it are sorted and visited.
  void Refine();

  // The top k, best first, with labels rolled (and mirrored back for the left hand) and shape
  // names.
  std::vector<Match> Matches() const;

  void AddInto(SearchStats* stats) const;

 private:
  double TotalPx(size_t i) const { return BoundPx(la_[i]) + BoundPx(lb_[i]); }

  // The pair (s * num_views + v) of entry e of la_ / lb_: e itself in exact search.
  size_t PairOf(size_t e) const { return pairs_.empty() ? e : pairs_[e]; }
  size_t SlotEntries(size_t s) const { return slot_begin_[s + 1] - slot_begin_[s]; }
  size_t GroupEntries(const std::vector<GridMember>& group) const;

  // L_A of a slot from its exact integer sum (1/2 px): floor(64 sum / 2 / |Q_s|).
  Bound CoarseABound(uint64_t sum, size_t s) const;

  // Every prepared slot's divider by its point count (CoarseABound), after PrepareSlot.
  void MakeQueryDividers();

  // L_A of one pair as CoarseBounds() computes it (kNoBound for a view without points, 0 without
  // coarse fields): sum_c n(c) F_v(c) is the same exact integer as the streaming product's.
  Bound PairCoarseBound(size_t v, size_t s) const;

  // L_A of every pair into la_ (kNoBound for views without points), or 0 without coarse fields.
  // L_A = sum / 2 / |Q| px with an exact integer sum, so floor(64 L_A) is an integer division.
  void CoarseBounds();

  // fn(block, v0, v1, sums) for every block of views [v0, v1) of the coarse fields, in
  // parallel, with a scratch array of kBlock sums.
  template <typename Fn>
  void ForEachViewBlock(Fn fn) {
    ParallelFor(
        coarse_->num_blocks(),
        threads_,
        [&](size_t b, int) {
          std::array<uint32_t, CoarseFields::kBlock> sums;
          const size_t v0 = b * CoarseFields::kBlock;
          fn(b, v0, std::min(num_views_, v0 + CoarseFields::kBlock), sums.data());
          return true;
        },
        pool_);
  }

  // L_A with the neighbour terms for the groups of 32 views of each block and slot that hold a
  // pair still at or below the k-th best after the seed; the others keep the cell-only L_A of
  // CoarseBounds (a smaller bound, and their pairs are already above the k-th best, which only
  // falls). On real photos ~70-90% of the groups are skipped.
  void NeighbourBounds();

  // Every slot's coarse field (SlotFields), one ComputeCoarseField per R/4 rolls: with R a
  // multiple of 4 the grid groups' bases are rolls r < R/2 of the right hand (or of the one
  // hand searched), and base r + R/4 is base r quarter-turned (CopyQuarterTurned); each group's
  // members are its base flipped (CopyFlipped). Every copy subtracts its measured gap.
  void PrepareSlotFields();

  // The fields of a grid group's members from its base's: flipped, less their gaps.
  void CopyMembers(const std::vector<GridMember>& group);

  // L_Bc from its exact integer sum (1/2 px) for a view: floor(64 sum / 2 / |Y_v|), `ny` dividing
  // by |Y_v|.
  static Bound CoarseBBound(uint64_t sum, const FloorDivider& ny);

  // L_Bc of views [v0, v1) for every slot into lb_: sum_c n_v(c) G_s(c) / 2 / |Y_v| px, an exact
  // integer sum, so floor(64 L_Bc) is an integer division (coarse_bound.h).
  void CoarseBBounds(size_t v0, size_t v1);

  // No pair i above it can enter the top k (the k-th best, or its view's shape's bound).
  double ThresholdFor(uint32_t i) const;

  // Pairs by their bound L_A + L_B, then by index.
  bool ByBound(uint32_t x, uint32_t y) const;

  // The (at most) m pairs of [begin, end) not yet scored that come first under `less`, sorted by
  // it: a bounded max-heap, no range-sized index array.
  template <typename Less>
  std::vector<uint32_t> SmallestPairs(size_t begin, size_t end, size_t m, Less less) const {
    std::vector<uint32_t> best;
    best.reserve(m + 1);
    for (uint32_t i = static_cast<uint32_t>(begin); i < end; ++i) {
      if (la_[i] == kNoBound) continue;
      if (best.size() < m) {
        best.push_back(i);
        std::push_heap(best.begin(), best.end(), less);
      } else if (m > 0 && less(i, best.front())) {
        std::pop_heap(best.begin(), best.end(), less);
        best.back() = i;
        std::push_heap(best.begin(), best.end(), less);
      }
    }
    std::sort(best.begin(), best.end(), less);
    return best;
  }

  // Scores the pairs with the smallest L_A (a few times k), best first, and marks them scored.
  // With a per-shape limit also each shape's pair of smallest L_A: the seed's pairs are mostly
  // one shape's rolls and views, which would leave the k-th best shape, the bound of every shape
  // not yet scored, at +inf.
  void Seed();

  // Each grid group with entries by its smallest L_A (L_A + L_Bc), to visit the most promising
  // grids first, as (bound, group); sets every member's gap to its base. A group without entries
  // (indexed search: no candidate in its slots) builds no grid.
  std::vector<std::pair<Bound, size_t>> GridOrder(std::vector<std::vector<GridMember>>& groups);
  // Step d of Bounds(): L_B per grid group, most promising first, and each slot's best pairs
  // scored.
  void FineBounds();

  // L_B into lb_ for every pair of the member's slot whose L_A is <= the k-th best, from the
  // group's grid read through the member's flip, minus its gap.
  void BoundSlot(const DistanceGrid& grid, const GridMember& m);

  // Scores this slot's most promising pairs now so later groups can stop early (k pairs while
  // fewer than k are known, then 2).
  void ScoreSlotBest(size_t s, int worker);

  // Scores pair i unless its bound is above the k-th best, and marks it scored (kNoBound), so
  // that Refine does not score it again (its D_c is in the top k already, or was above the
  // threshold, which only falls).
  void ScorePair(uint32_t i, int worker);

  // Scores the pairs of `order` (increasing bound) until a bound exceeds the k-th best.
  void Visit(std::span<const uint32_t> order);

  // Scores the pairs of `pairs` whose bound is at or below the k-th best when they are reached,
  // one view at a time (Refine).
  void VisitByView(std::vector<uint32_t> pairs, Progress* progress);

  // Scores pair i, visited with the k-th best at `threshold`, into the top k.
  void ScoreVisited(uint32_t i, double threshold, int worker);

  // One phase's progress line (SearchOptions::progress), e.g. "query refine (both hands)".
  std::unique_ptr<Progress> MakeProgress(const std::string& phase,
                                         uint64_t total,
                                         const char* unit) const;

  const Database& db_;
  std::span<const int32_t> max_abs_;
  float grid_half_extent_px_;
  const CoarseFields* coarse_;
  const ViewHistograms* view_histograms_;  // nullptr: no coarse B bound
  SlotFields slot_fields_;
  const SearchOptions& options_;
  const int threads_;
  ThreadPool* const pool_;
  const size_t num_views_;
  const uint32_t num_rolls_;
  const size_t k_;
  SearchContext ctx_;
  std::span<const uint32_t> shape_of_;  // per view: dense shape index (empty: no per-shape limit)
  size_t num_shapes_;
  TopK top_;
  // Per pair (indexed search: per candidate pair, pairs_): L_A (kNoBound: a view without points,
  // or a pair already scored) and L_B (0 until computed), both rounded down to 1/64 px;
  // L = L_A + L_B <= D_c.
  std::vector<Bound> la_;
  std::vector<Bound> lb_;
  std::vector<FloorDivider> query_divider_;  // per slot: by its rolled query's point count
  // Indexed search: each entry's pair (s * num_views + v), increasing; empty in exact search,
  // where entry i is pair i. The entries of slot s are [slot_begin_[s], slot_begin_[s + 1]).
  std::vector<uint32_t> pairs_;
  std::vector<size_t> slot_begin_;
  std::atomic<uint64_t> grids_{0};
  std::atomic<uint64_t> grid_bounded_{0};
  std::atomic<uint64_t> refined_{0};
  std::atomic<uint64_t> abandoned_{0};
  const std::chrono::steady_clock::time_point progress_since_;
};

}  // namespace search_internal
}  // namespace handdb
