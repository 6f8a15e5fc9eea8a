// Memory for large buffers that are written once and read often -- the landmark model's (the
// file's bytes, the float weights, XNNPACK's packed weights and activations) and the exact
// search's cell-major coarse fields -- carved from 2 MiB-aligned mappings advised for transparent
// huge pages. Loading the full landmark model first-touches ~30 MB: in 4 KiB pages that is ~8000
// page faults, which on a virtual machine cost ~17 us each (40 MB: 170 ms, against 3.5 ms in huge
// pages; docs/decisions/0013-landmark-network-on-xnnpack.md); the paper database's coarse fields
// are 4 MB, ~1000 faults in small pages (docs/decisions/0018). Where the kernel gives no huge
// pages (transparent_hugepage=never) the mappings are plain ones: slower, the same results.
// Under AddressSanitizer the blocks are plain heap blocks, checked like any other.
#pragma once

#include <cstddef>
#include <new>

namespace handdb {

// `bytes` aligned to `alignment` (a power of two, at most 4096); nullptr when the system has no
// memory left. Thread-safe. A block of 1 MiB or more gets mappings of its own; smaller ones share
// 2 MiB chunks, each unmapped when its last block is freed.
void* AllocateHuge(size_t bytes, size_t alignment);
// Frees a block of AllocateHuge (nullptr: nothing).
void FreeHuge(void* p);

// A std::vector allocator over AllocateHuge.
template <typename T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() = default;
  template <typename U>
  HugePageAllocator(const HugePageAllocator<U>&) {}  // NOLINT(google-explicit-constructor)
  T* allocate(size_t n) {
    if (n > static_cast<size_t>(-1) / sizeof(T)) throw std::bad_alloc();
    void* p = AllocateHuge(n * sizeof(T), alignof(T) < 64 ? 64 : alignof(T));
    if (p == nullptr) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t) { FreeHuge(p); }
  template <typename U>
  bool operator==(const HugePageAllocator<U>&) const {
    return true;
  }
};

}  // namespace handdb
