#include "query/search_run.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "base/thread_pool.h"

namespace handdb::search_internal {

// The slots of a search, the first hand's rolls first: right, left, or right then left.
std::vector<Slot> MakeSlots(Hand hand, uint32_t rolls) {
  std::vector<Slot> slots;
  for (Hand h : {Hand::kRight, Hand::kLeft}) {
    if (hand != Hand::kEither && hand != h) continue;
    for (roll_id_t r = 0; r < rolls; ++r) slots.push_back({h, r});
  }
  return slots;
}

// The slots that share one distance grid, the base (kNone) first. With R even, roll r + R/2 is
// roll r turned by 180 degrees (kXY). The left hand's roll r' is the right hand's roll R - r'
// mirrored in x: rot(-a) M X = M rot(a) X with M = diag(-1, 1), and a = -angle(R - r') (kX), and
// its roll R/2 - r is then the right roll r + R/2 mirrored, i.e. roll r reflected in y (kY). So a
// both-hand search needs R/2 grids for its 2R slots (docs/query.md); MakeFineGridGroups halves
// that.
std::vector<std::vector<GridMember>> MakeGridGroups(size_t num_slots, uint32_t rolls) {
  const bool halves = rolls >= 2 && rolls % 2 == 0;
  const bool both = num_slots == 2 * static_cast<size_t>(rolls);
  std::vector<std::vector<GridMember>> groups;
  for (uint32_t r = 0; r < (halves ? rolls / 2 : rolls); ++r) {
    std::vector<GridMember> g = {{r, GridFlip::kNone}};
    if (halves) g.push_back({r + rolls / 2, GridFlip::kXY});
    if (both) {
      g.push_back({rolls + (rolls - r) % rolls, GridFlip::kX});
      if (halves) g.push_back({rolls + rolls / 2 - r, GridFlip::kY});
    }
    groups.push_back(std::move(g));
  }
  return groups;
}

std::vector<std::vector<GridMember>> MakeFineGridGroups(size_t num_slots, uint32_t rolls) {
  std::vector<std::vector<GridMember>> groups = MakeGridGroups(num_slots, rolls);
  if (rolls % 4 != 0) return groups;
  const size_t quarter = rolls / 4;
  for (size_t g = 0; g < quarter; ++g) {
    for (GridMember m : groups[g + quarter]) {
      m.turned = true;
      groups[g].push_back(m);
    }
  }
  groups.resize(quarter);
  return groups;
}

SearchRun::SearchRun(const SearchInputs& in,
                     std::span<const Point2f> query_px,
                     const SearchOptions& options)
    : db_(*in.db),
      max_abs_(in.max_abs),
      grid_half_extent_px_(in.grid_half_extent_px),
      coarse_(in.coarse),
      view_histograms_(in.coarse != nullptr ? in.view_histograms : nullptr),
      options_(options),
      threads_(in.threads),
      pool_(in.pool),
      num_views_(in.db->num_views()),
      num_rolls_(in.db->num_rolls()),
      k_(static_cast<size_t>(options.top_k)),
      ctx_(*in.db,
           in.max_abs,
           in.y_sorted,
           in.coarse,
           query_px,
           MakeSlots(options.hand, in.db->num_rolls()),
           options,
           in.threads),
      shape_of_(options.max_per_shape > 0 ? in.shape_of : std::span<const uint32_t>()),
      num_shapes_(in.num_shapes),
      top_(k_, kInf, options.max_per_shape, in.shape_of, in.num_shapes),
      progress_since_(in.progress_since) {}

void SearchRun::BruteForce(SearchStats* stats, std::chrono::steady_clock::time_point start) {
  ParallelFor(
      num_slots(),
      threads_,
      [&](size_t s, int) {
        ctx_.PrepareSlot(s);
        return true;
      },
      pool_);
  stats->seconds_bounds = SecondsSince(start);
  const auto refine_start = std::chrono::steady_clock::now();
  const auto progress = MakeProgress("brute force", num_views_ * num_slots(), "pairs");
  ParallelFor(
      num_views_,
      threads_,
      [&](size_t v, int worker) {
        if (db_.point_count(static_cast<view_id_t>(v)) != 0) {
          for (size_t s = 0; s < num_slots(); ++s) {
            Scored sc;
            ctx_.Score(static_cast<view_id_t>(v), s, kInf, 0.0, worker, &sc);
            top_.Insert(sc);
          }
          refined_.fetch_add(num_slots(), std::memory_order_relaxed);
        }
        progress->Add(num_slots());
        return true;
      },
      pool_);
  stats->seconds_refine = SecondsSince(refine_start);
}

void SearchRun::Bounds() {
  const size_t n = num_views_ * num_slots();
  la_.assign(n, 0);
  lb_.assign(n, 0);
  slot_begin_.resize(num_slots() + 1);
  for (size_t s = 0; s <= num_slots(); ++s) slot_begin_[s] = s * num_views_;
  ParallelFor(
      num_slots(),
      threads_,
      [&](size_t s, int) {
        ctx_.PrepareSlot(s);
        return true;
      },
      pool_);
  MakeQueryDividers();
  if (view_histograms_ != nullptr) PrepareSlotFields();
  CoarseBounds();
  if (coarse_ != nullptr) {
    Seed();
    NeighbourBounds();
  }
  FineBounds();
}

void SearchRun::BoundCandidates(std::vector<uint32_t> pairs) {
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  pairs_ = std::move(pairs);
  la_.assign(pairs_.size(), 0);
  lb_.assign(pairs_.size(), 0);
  slot_begin_.assign(num_slots() + 1, 0);
  for (uint32_t p : pairs_) ++slot_begin_[p / num_views_ + 1];
  for (size_t s = 0; s < num_slots(); ++s) slot_begin_[s + 1] += slot_begin_[s];
  // Every slot of a group holding a candidate: FineBounds builds the grid from the group's base
  // and measures each member's gap to it.
  std::vector<size_t> prepare;
  for (const std::vector<GridMember>& group : MakeFineGridGroups(num_slots(), num_rolls_)) {
    if (GroupEntries(group) == 0) continue;
    for (const GridMember& m : group) prepare.push_back(m.slot);
  }
  ParallelFor(
      prepare.size(),
      threads_,
      [&](size_t j, int) {
        ctx_.PrepareSlot(prepare[j]);
        return true;
      },
      pool_);
  MakeQueryDividers();
  ParallelFor(
      pairs_.size(),
      threads_,
      [&](size_t e, int) {
        la_[e] = PairCoarseBound(pairs_[e] % num_views_, pairs_[e] / num_views_);
        return true;
      },
      pool_);
  if (coarse_ != nullptr) Seed();
  FineBounds();
}

void SearchRun::Refine() {
  const size_t n = la_.size();
  auto by_bound = [&](uint32_t x, uint32_t y) { return ByBound(x, y); };
  const std::vector<uint32_t> first = SmallestPairs(0, n, k_, by_bound);
  Visit(first);
  std::vector<uint32_t> rest;
  const uint32_t last_first = first.empty() ? 0 : first.back();
  for (uint32_t i = 0; i < n; ++i) {
    if (la_[i] != kNoBound && TotalPx(i) <= ThresholdFor(i) &&
        (first.empty() || by_bound(last_first, i))) {
      rest.push_back(i);
    }
  }
  // `rest` bounds the pairs to refine. They are visited one view at a time (its pairs in
  // increasing bound, the views by their smallest bound): the pairs of one view read the same
  // points, row index and coarse-field cache lines, and the seeded k-th best is already near
  // its final value, so visiting by view refines about the same pairs as visiting by bound.
  const auto progress = MakeProgress("refine", rest.size(), "pairs");
  VisitByView(std::move(rest), progress.get());
  progress->SetTotal(progress->done());
}

void SearchRun::AddInto(SearchStats* stats) const {
  stats->bounded += la_.size();
  stats->grids += grids_.load();
  stats->grid_bounded += grid_bounded_.load();
  stats->refined += refined_.load();
  stats->abandoned += abandoned_.load();
  stats->view_trees += ctx_.num_view_trees();
  stats->probe_abandoned += ctx_.num_probe_abandoned();
}

size_t SearchRun::GroupEntries(const std::vector<GridMember>& group) const {
  size_t n = 0;
  for (const GridMember& m : group) n += SlotEntries(m.slot);
  return n;
}

Bound SearchRun::CoarseABound(uint64_t sum, size_t s) const {
  const uint64_t units = query_divider_[s](sum * static_cast<uint64_t>(kBoundUnitsPerPx / 2));
  return static_cast<Bound>(std::min<uint64_t>(units, kBoundMax));
}

void SearchRun::MakeQueryDividers() {
  query_divider_.clear();
  for (size_t s = 0; s < num_slots(); ++s) {
    query_divider_.emplace_back(std::max<uint64_t>(1, ctx_.rolled(s).size()));
  }
}

Bound SearchRun::PairCoarseBound(size_t v, size_t s) const {
  if (db_.point_count(static_cast<view_id_t>(v)) == 0) return kNoBound;
  if (coarse_ == nullptr) return 0;
  return CoarseABound(coarse_->PairSum(ctx_.histogram(s), v), s);
}

void SearchRun::CoarseBounds() {
  if (coarse_ == nullptr) {
    for (size_t s = 0; s < num_slots(); ++s) {
      for (view_id_t v = 0; v < num_views_; ++v) {
        if (db_.point_count(v) == 0) la_[s * num_views_ + v] = kNoBound;
      }
    }
    return;
  }
  ForEachViewBlock([&](size_t b, size_t v0, size_t v1, uint32_t* sums) {
    for (size_t s = 0; s < num_slots(); ++s) {
      coarse_->BlockSums(ctx_.histogram(s), b, sums, /*neighbours=*/false);
      for (size_t v = v0; v < v1; ++v) {
        la_[s * num_views_ + v] = db_.point_count(static_cast<view_id_t>(v)) == 0
                                      ? kNoBound
                                      : CoarseABound(sums[v - v0], s);
      }
    }
    if (view_histograms_ != nullptr) CoarseBBounds(v0, v1);
  });
}

void SearchRun::NeighbourBounds() {
  ForEachViewBlock([&](size_t b, size_t v0, size_t v1, uint32_t* sums) {
    for (size_t s = 0; s < num_slots(); ++s) {
      const double threshold = top_.threshold();
      unsigned groups = 0;
      for (size_t v = v0; v < v1; ++v) {
        const size_t e = s * num_views_ + v;
        if (la_[e] == kNoBound) continue;
        const double t =
            shape_of_.empty() ? threshold : top_.ThresholdFor(static_cast<view_id_t>(v));
        if (TotalPx(e) <= t) groups |= 1u << ((v - v0) / 32);
      }
      if (groups == 0) continue;
      coarse_->BlockSums(ctx_.histogram(s), b, sums, /*neighbours=*/true, groups);
      for (size_t v = v0; v < v1; ++v) {
        const size_t e = s * num_views_ + v;
        if (la_[e] == kNoBound || (groups >> ((v - v0) / 32) & 1) == 0) continue;
        la_[e] = std::max(la_[e], CoarseABound(sums[v - v0], s));
      }
    }
  });
}

void SearchRun::PrepareSlotFields() {
  const std::vector<std::vector<GridMember>> groups = MakeGridGroups(num_slots(), num_rolls_);
  slot_fields_.Reset(num_slots());
  const size_t quarter = num_rolls_ % 4 == 0 ? num_rolls_ / 4 : 0;
  const size_t computed = quarter > 0 ? quarter : groups.size();
  ParallelFor(
      computed,
      threads_,
      [&](size_t g, int) {
        const size_t base = groups[g][0].slot;
        slot_fields_.Compute(base, ctx_.rolled(base));
        CopyMembers(groups[g]);
        if (quarter > 0) {
          GridMember turned = groups[g + quarter][0];  // base r + R/4: T of base r
          turned.turned = true;
          slot_fields_.CopyQuarterTurned(base, turned.slot, ctx_.MemberGap(base, turned));
          CopyMembers(groups[g + quarter]);
        }
        return true;
      },
      pool_);
}

void SearchRun::CopyMembers(const std::vector<GridMember>& group) {
  const size_t base = group[0].slot;
  for (size_t i = 1; i < group.size(); ++i) {
    const GridMember& m = group[i];
    slot_fields_.CopyFlipped(base, m.slot, m.flip, ctx_.MemberGap(base, m));
  }
}

Bound SearchRun::CoarseBBound(uint64_t sum, const FloorDivider& ny) {
  const uint64_t units = ny(sum * static_cast<uint64_t>(kBoundUnitsPerPx / 2));
  return static_cast<Bound>(std::min<uint64_t>(units, kBoundMax));
}

void SearchRun::CoarseBBounds(size_t v0, size_t v1) {
  thread_local std::vector<uint32_t> sums;
  sums.resize(slot_fields_.stride());
  for (size_t v = v0; v < v1; ++v) {
    const size_t ny = db_.point_count(static_cast<view_id_t>(v));
    if (ny == 0) continue;
    view_histograms_->Sums(v, slot_fields_, sums.data());
    const FloorDivider divider(ny);
    for (size_t s = 0; s < num_slots(); ++s) {
      lb_[s * num_views_ + v] = CoarseBBound(sums[s], divider);
    }
  }
}

double SearchRun::ThresholdFor(uint32_t i) const {
  if (shape_of_.empty()) return top_.threshold();
  return top_.ThresholdFor(static_cast<view_id_t>(PairOf(i) % num_views_));
}

bool SearchRun::ByBound(uint32_t x, uint32_t y) const {
  const uint32_t tx = static_cast<uint32_t>(la_[x]) + lb_[x];
  const uint32_t ty = static_cast<uint32_t>(la_[y]) + lb_[y];
  return tx != ty ? tx < ty : x < y;
}

void SearchRun::Seed() {
  auto less = [&](uint32_t x, uint32_t y) { return ByBound(x, y); };
  std::vector<uint32_t> best = SmallestPairs(0, la_.size(), 2 * k_ + 8, less);
  if (!shape_of_.empty()) {
    std::vector<uint32_t> per_shape(num_shapes_, UINT32_MAX);
    for (uint32_t i = 0; i < la_.size(); ++i) {
      if (la_[i] == kNoBound) continue;
      uint32_t& b = per_shape[shape_of_[PairOf(i) % num_views_]];
      if (b == UINT32_MAX || less(i, b)) b = i;
    }
    for (uint32_t i : per_shape) {
      if (i != UINT32_MAX) best.push_back(i);
    }
    std::sort(best.begin(), best.end(), less);
    best.erase(std::unique(best.begin(), best.end()), best.end());
  }
  ParallelFor(
      best.size(),
      threads_,
      [&](size_t j, int worker) {
        ScorePair(best[j], worker);
        return true;
      },
      pool_);
}

std::vector<std::pair<Bound, size_t>> SearchRun::GridOrder(
    std::vector<std::vector<GridMember>>& groups) {
  std::vector<std::pair<Bound, size_t>> order;
  for (size_t g = 0; g < groups.size(); ++g) {
    if (GroupEntries(groups[g]) == 0) continue;
    Bound best = kNoBound;
    for (GridMember& m : groups[g]) {
      m.gap_px = ctx_.MemberGap(groups[g][0].slot, m);
      if (SlotEntries(m.slot) == 0) continue;
      for (size_t e = slot_begin_[m.slot]; e < slot_begin_[m.slot + 1]; ++e) {
        if (la_[e] == kNoBound) continue;
        best = static_cast<Bound>(
            std::min<uint32_t>(best, std::min<uint32_t>(kNoBound - 1, la_[e] + lb_[e])));
      }
    }
    order.emplace_back(best, g);
  }
  std::sort(order.begin(), order.end());
  return order;
}

void SearchRun::FineBounds() {
  auto groups = MakeFineGridGroups(num_slots(), num_rolls_);
  const std::vector<std::pair<Bound, size_t>> order = GridOrder(groups);
  const DistanceGridOptions grid_options{options_.dt_cell_px, grid_half_extent_px_};
  std::vector<DistanceGrid> grids(threads_, DistanceGrid(grid_options));
  size_t progress_slots = 0;
  for (const auto& entry : order) progress_slots += groups[entry.second].size();
  const auto progress = MakeProgress("bounds", progress_slots, "rolls");
  ParallelFor(
      order.size(),
      threads_,
      [&](size_t i, int worker) {
        const std::vector<GridMember>& group = groups[order[i].second];
        if (BoundPx(order[i].first) <= top_.threshold()) {
          DistanceGrid& grid = grids[worker];
          grid.Build(ctx_.rolled(group[0].slot));
          grids_.fetch_add(1, std::memory_order_relaxed);
          for (const GridMember& m : group) {
            BoundSlot(grid, m);
            ScoreSlotBest(m.slot, worker);
          }
        }
        progress->Add(group.size());
        return true;
      },
      pool_);
}

void SearchRun::BoundSlot(const DistanceGrid& grid, const GridMember& m) {
  constexpr size_t kChunk = 64;
  uint64_t bounded = 0;
  for (size_t e = slot_begin_[m.slot]; e < slot_begin_[m.slot + 1]; ++e) {
    const Bound la = la_[e];
    if (la == kNoBound) continue;
    const auto v = static_cast<view_id_t>(PairOf(e) % num_views_);
    const double threshold = top_.ThresholdFor(v);
    if (TotalPx(e) > threshold) continue;
    const std::span<const PointQ> pts = db_.SearchPoints(v);
    const double n = static_cast<double>(pts.size());
    const double limit = Limit(threshold, BoundPx(la), n) + m.gap_px * n;
    const bool fast = grid.Covers(max_abs_[v]);
    double sum = 0;
    for (size_t i = 0; i < pts.size() && sum <= limit; i += kChunk) {
      const auto chunk = pts.subspan(i, std::min(kChunk, pts.size() - i));
      sum += fast ? grid.SumLowerBoundsFast(chunk, m.flip, m.turned)
                  : grid.SumLowerBounds(chunk, m.flip, m.turned);
    }
    const double mean = sum / n;
    lb_[e] = std::max(
        lb_[e], BoundBelow(mean - DistanceGrid::MeanLowerBoundMargin(pts.size(), mean) - m.gap_px));
    ++bounded;
  }
  grid_bounded_.fetch_add(bounded, std::memory_order_relaxed);
}

void SearchRun::ScoreSlotBest(size_t s, int worker) {
  const size_t m = std::min<size_t>(SlotEntries(s), top_.threshold() == kInf ? k_ : 2);
  auto by_bound = [&](uint32_t x, uint32_t y) { return ByBound(x, y); };
  for (uint32_t i : SmallestPairs(slot_begin_[s], slot_begin_[s + 1], m, by_bound)) {
    ScorePair(i, worker);
  }
}

void SearchRun::ScorePair(uint32_t i, int worker) {
  const double threshold = ThresholdFor(i);
  if (TotalPx(i) > threshold) return;
  ScoreVisited(i, threshold, worker);
  la_[i] = kNoBound;
}

void SearchRun::Visit(std::span<const uint32_t> order) {
  ParallelFor(
      order.size(),
      threads_,
      [&](size_t j, int worker) {
        const uint32_t i = order[j];
        if (TotalPx(i) > top_.threshold()) return false;  // every later pair: a larger bound
        const double threshold = ThresholdFor(i);
        if (TotalPx(i) > threshold) return true;  // above its shape's bound
        ScoreVisited(i, threshold, worker);
        return true;
      },
      pool_);
}

void SearchRun::VisitByView(std::vector<uint32_t> pairs, Progress* progress) {
  auto view_of = [&](uint32_t i) { return PairOf(i) % num_views_; };
  std::sort(pairs.begin(), pairs.end(), [&](uint32_t x, uint32_t y) {
    const size_t vx = view_of(x);
    const size_t vy = view_of(y);
    return vx != vy ? vx < vy : ByBound(x, y);
  });
  // Each view's run of pairs, by the bound of its first (smallest) pair.
  std::vector<std::pair<uint32_t, uint32_t>> runs;  // [begin, end) in `pairs`
  for (size_t b = 0; b < pairs.size();) {
    size_t e = b + 1;
    while (e < pairs.size() && view_of(pairs[e]) == view_of(pairs[b])) ++e;
    runs.emplace_back(static_cast<uint32_t>(b), static_cast<uint32_t>(e));
    b = e;
  }
  std::sort(runs.begin(), runs.end(), [&](const auto& x, const auto& y) {
    return ByBound(pairs[x.first], pairs[y.first]);
  });
  ParallelFor(
      runs.size(),
      threads_,
      [&](size_t r, int worker) {
        for (uint32_t j = runs[r].first; j < runs[r].second; ++j) {
          const uint32_t i = pairs[j];
          const double threshold = ThresholdFor(i);
          if (TotalPx(i) > threshold) break;  // the view's later pairs: larger bounds
          if (progress != nullptr) progress->Add();
          ScoreVisited(i, threshold, worker);
        }
        return true;
      },
      pool_);
}

void SearchRun::ScoreVisited(uint32_t i, double threshold, int worker) {
  const auto v = static_cast<view_id_t>(PairOf(i) % num_views_);
  const size_t s = PairOf(i) / num_views_;
  refined_.fetch_add(1, std::memory_order_relaxed);
  Scored sc;
  if (ctx_.Score(v, s, threshold, BoundPx(lb_[i]), worker, &sc)) {
    sc.lower_bound = TotalPx(i);
    top_.Insert(sc);
  } else {
    abandoned_.fetch_add(1, std::memory_order_relaxed);
  }
}

std::vector<Match> SearchRun::Matches() const {
  std::vector<Match> matches;
  for (const Scored& s : top_.items()) {
    Match m;
    m.view_id = s.view;
    m.roll = s.roll;
    m.roll_angle = RollAngle(s.roll, num_rolls_);
    m.distance = s.distance;
    m.a = s.a;
    m.b = s.b;
    m.lower_bound = s.lower_bound;
    m.label = RollLabel(db_.label(s.view), m.roll_angle);
    if (s.hand == Hand::kLeft) m.label = MirrorLabel(m.label);
    m.hand = s.hand;
    m.shape_name = std::string(db_.shape_name(m.label.shape_id));
    matches.push_back(std::move(m));
  }
  return matches;
}

std::unique_ptr<Progress> SearchRun::MakeProgress(const std::string& phase,
                                                  uint64_t total,
                                                  const char* unit) const {
  std::string label = "query " + phase;
  if (options_.hand == Hand::kEither) label += " (both hands)";
  auto progress = std::make_unique<Progress>(label, total, options_.progress, unit);
  progress->QuietUnlessSlow(progress_since_);
  return progress;
}

}  // namespace handdb::search_internal
