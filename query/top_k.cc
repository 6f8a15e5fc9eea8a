#include "query/top_k.h"

#include <algorithm>
#include <map>
#include <utility>

namespace handdb {

std::vector<Match> LimitPerShape(std::vector<Match> sorted, int top_k, int max_per_shape) {
  std::vector<Match> out;
  std::map<uint32_t, int> per_shape;
  for (Match& m : sorted) {
    if (static_cast<int>(out.size()) >= top_k) break;
    if (max_per_shape > 0 && ++per_shape[m.label.shape_id] > max_per_shape) continue;
    out.push_back(std::move(m));
  }
  return out;
}

namespace search_internal {

void TopK::Insert(Scored s) {
  if (max_per_shape_ > 0) s.shape = shape_of_[s.view];
  if (s.distance > ThresholdFor(s.view)) return;
  std::lock_guard<std::mutex> lock(mu_);
  if (items_.size() == k_ && !Before(s, items_.back())) return;
  // A pair is scored once (SearchRun::ScorePair marks what it scored); kept as a guard.
  for (const Scored& it : items_) {
    if (it.view == s.view && it.roll == s.roll && it.hand == s.hand) return;
  }
  if (max_per_shape_ > 0 && !AdmitToShape(s)) return;
  items_.insert(std::upper_bound(items_.begin(), items_.end(), s, Before), s);
  if (items_.size() > k_) items_.pop_back();
  if (items_.size() == k_) {
    threshold_.store(std::min(threshold_.load(std::memory_order_relaxed), items_.back().distance),
                     std::memory_order_relaxed);
  }
}

bool TopK::AdmitToShape(const Scored& s) {
  // The shape's m best distances so far (of pairs that reached here: the others are above
  // the k-th best, so they would never lower a bound below it).
  std::vector<double>& best = shape_best_[s.shape];
  best.insert(std::upper_bound(best.begin(), best.end(), s.distance), s.distance);
  if (best.size() > static_cast<size_t>(max_per_shape_)) best.pop_back();
  if (best.size() == static_cast<size_t>(max_per_shape_)) {
    shape_threshold_[s.shape].store(best.back(), std::memory_order_relaxed);
  }
  int same = 0;
  size_t worst = 0;
  for (size_t i = 0; i < items_.size(); ++i) {
    if (items_[i].shape == s.shape) {
      ++same;
      worst = i;
    }
  }
  if (same >= max_per_shape_) {
    if (!Before(s, items_[worst])) return false;
    items_.erase(items_.begin() + static_cast<std::ptrdiff_t>(worst));
  }
  return true;
}

}  // namespace search_internal
}  // namespace handdb
