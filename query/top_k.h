// The order of search results and the shared top k a search fills (query/searcher.h): the
// total order (D_c, view id, roll, right before left), and the per-shape limit, which
// LimitPerShape also applies to a list re-ranked after the search (pose/landmark_rank.h).
#pragma once

#include <atomic>
#include <cstddef>
#include <mutex>
#include <span>
#include <vector>

#include "format/view.h"
#include "query/searcher.h"

namespace handdb {

// The first top_k matches of `sorted` (best first) with at most max_per_shape of each basic shape
// (label.shape_id; 0: no limit), in their order: what SearchOptions::max_per_shape means, for a
// list ordered by something other than D_c.
std::vector<Match> LimitPerShape(std::vector<Match> sorted, int top_k, int max_per_shape);

namespace search_internal {

struct Scored {
  double distance = 0;
  double a = 0;
  double b = 0;
  double lower_bound = 0;
  view_id_t view = 0;
  roll_id_t roll = 0;
  Hand hand = Hand::kRight;
  shape_id_t shape = kInvalidShapeId;  // set by TopK when it limits matches per shape
};

// The total order of results: distance, then view id, then roll, then right before left.
inline bool Before(const Scored& x, const Scored& y) {
  if (x.distance != y.distance) return x.distance < y.distance;
  if (x.view != y.view) return x.view < y.view;
  if (x.roll != y.roll) return x.roll < y.roll;
  return x.hand == Hand::kRight && y.hand == Hand::kLeft;
}

// Shared top-k under a mutex; threshold() is the k-th best distance (+inf until k are known),
// readable without the lock. With a per-shape limit m > 0 (SearchOptions::max_per_shape) it keeps
// the k best pairs among each shape's m best: a pair whose shape already holds m better pairs is
// refused, a better one replaces that shape's worst; a pair pushed out never returns, since every
// position of the list only improves. Each shape also has its own bound, the m-th best distance
// of its pairs scored so far: a pair above it cannot enter (m better pairs of its shape exist),
// so ThresholdFor(view) = min(k-th best, the view's shape's bound) prunes like threshold() does,
// and far more on the shapes that fill the top of the list (a shape's other rolls and views).
class TopK {
 public:
  // `bound`: pairs above it are never wanted (+inf: every pair may be). `shape_of`: each view's
  // dense shape index (< num_shapes), needed when max_per_shape > 0.
  TopK(size_t k,
       double bound,
       int max_per_shape,
       std::span<const uint32_t> shape_of,
       size_t num_shapes)
      : k_(k),
        max_per_shape_(max_per_shape),
        shape_of_(shape_of),
        shape_best_(max_per_shape > 0 ? num_shapes : 0),
        shape_threshold_(max_per_shape > 0 ? num_shapes : 0),
        threshold_(bound) {
    items_.reserve(k + 1);
    for (std::atomic<double>& t : shape_threshold_) t.store(bound, std::memory_order_relaxed);
  }

  void Insert(Scored s);
  // The k-th best distance: no pair above it enters.
  double threshold() const { return threshold_.load(std::memory_order_relaxed); }
  // No pair of view v above it enters (threshold() without a per-shape limit).
  double ThresholdFor(view_id_t v) const {
    const double t = threshold();
    if (max_per_shape_ == 0) return t;
    return std::min(t, shape_threshold_[shape_of_[v]].load(std::memory_order_relaxed));
  }
  std::vector<Scored> items() const { return items_; }

 private:
  // With a per-shape limit: records s in its shape's bound, and makes room for s among its
  // shape's pairs in the list (dropping the shape's worst); false when s cannot enter.
  bool AdmitToShape(const Scored& s);

  size_t k_;
  int max_per_shape_;
  std::span<const uint32_t> shape_of_;
  std::mutex mu_;
  std::vector<Scored> items_;
  std::vector<std::vector<double>> shape_best_;
  std::vector<std::atomic<double>> shape_threshold_;
  std::atomic<double> threshold_;
};

}  // namespace search_internal
}  // namespace handdb
