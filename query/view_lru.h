// A worker's few most recently used per-view structures (a view's row index, buckets or
// kd-tree). The search visits pairs in increasing bound and the rolls of one view have similar
// bounds, so the few rolls of a view that are refined close together build its structure once.
#pragma once

#include <algorithm>
#include <cstddef>
#include <utility>
#include <vector>

#include "format/view.h"

namespace handdb {

template <class Value, size_t kCapacity>
class ViewLru {
 public:
  static_assert(kCapacity > 0);

  // View v's value, most recent first. When absent, the least recently used entry (or a new one
  // while fewer than kCapacity are held) is reused: build(value) makes it v's, reusing what the
  // value already allocated.
  template <class Build>
  Value& Get(view_id_t v, Build&& build) {
    for (size_t i = 0; i < entries_.size(); ++i) {
      if (entries_[i].first == v) {
        std::rotate(entries_.begin(), entries_.begin() + i, entries_.begin() + i + 1);
        return entries_.front().second;
      }
    }
    if (entries_.size() < kCapacity) entries_.emplace_back();
    std::rotate(entries_.begin(), entries_.end() - 1, entries_.end());
    // Invalid until built: a build that throws (a coded view that does not decode) leaves no
    // entry that claims to be v's.
    entries_.front().first = kInvalidViewId;
    build(entries_.front().second);
    entries_.front().first = v;
    return entries_.front().second;
  }

 private:
  std::vector<std::pair<view_id_t, Value>> entries_;
};

}  // namespace handdb
