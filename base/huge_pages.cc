#include "base/huge_pages.h"

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <mutex>
#include <vector>

// Under AddressSanitizer every block is an ordinary heap block, so a read past the end of the
// model file's bytes, a weight tensor or a coarse field is reported, as the fuzz targets rely on.
#if defined(__SANITIZE_ADDRESS__)
#define HANDDB_HUGE_PAGES_PLAIN_BLOCKS 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define HANDDB_HUGE_PAGES_PLAIN_BLOCKS 1
#endif
#endif

namespace handdb {
namespace {

constexpr size_t kHugePage = size_t{2} << 20;
constexpr size_t kOwnMappingBytes = size_t{1} << 20;

// A 2 MiB-aligned mapping of `bytes` (a multiple of 2 MiB), advised for huge pages.
char* MapAligned(size_t bytes) {
  void* raw = ::mmap(nullptr,
                     bytes + kHugePage,
                     PROT_READ | PROT_WRITE,
                     MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE,
                     -1,
                     0);
  if (raw == MAP_FAILED) return nullptr;
  const auto start = reinterpret_cast<uintptr_t>(raw);
  const uintptr_t aligned = (start + kHugePage - 1) & ~(kHugePage - 1);
  if (aligned > start) ::munmap(raw, aligned - start);
  const size_t tail = start + bytes + kHugePage - (aligned + bytes);
  if (tail > 0) ::munmap(reinterpret_cast<void*>(aligned + bytes), tail);
  // Advice only: without transparent huge pages the mapping works in small pages.
  ::madvise(reinterpret_cast<void*>(aligned), bytes, MADV_HUGEPAGE);
  return reinterpret_cast<char*>(aligned);
}

// A mapping and the blocks carved from it. `used` only grows while blocks are live; the mapping
// is unmapped when the last one is freed (the chunk new blocks come from is reset instead).
struct Chunk {
  char* base = nullptr;
  size_t size = 0;
  size_t used = 0;
  int live = 0;
};

struct Chunks {
  std::mutex mutex;
  std::vector<Chunk> chunks;  // the last one: where small blocks are carved
  int current = -1;
};

Chunks& State() {
  static Chunks* state = new Chunks;  // never destroyed: blocks may be freed during exit
  return *state;
}

}  // namespace

void* AllocateHuge(size_t bytes, size_t alignment) {
  if (bytes == 0) bytes = 1;
#ifdef HANDDB_HUGE_PAGES_PLAIN_BLOCKS
  return std::aligned_alloc(alignment, (bytes + alignment - 1) / alignment * alignment);
#endif
  Chunks& s = State();
  std::lock_guard<std::mutex> lock(s.mutex);
  if (bytes >= kOwnMappingBytes) {
    const size_t size = (bytes + kHugePage - 1) / kHugePage * kHugePage;
    char* base = MapAligned(size);
    if (base == nullptr) return nullptr;
    s.chunks.push_back({base, size, size, 1});  // appended: `current` stays valid
    return base;
  }
  if (s.current >= 0) {
    Chunk& c = s.chunks[s.current];
    const size_t offset = (c.used + alignment - 1) & ~(alignment - 1);
    if (offset + bytes <= c.size) {
      c.used = offset + bytes;
      ++c.live;
      return c.base + offset;
    }
  }
  char* base = MapAligned(kHugePage);
  if (base == nullptr) return nullptr;
  // The old carving chunk becomes an ordinary one; an empty one is unmapped now.
  if (s.current >= 0 && s.chunks[s.current].live == 0) {
    ::munmap(s.chunks[s.current].base, s.chunks[s.current].size);
    s.chunks.erase(s.chunks.begin() + s.current);
  }
  s.chunks.push_back({base, kHugePage, bytes, 1});
  s.current = static_cast<int>(s.chunks.size()) - 1;
  return base;
}

void FreeHuge(void* p) {
  if (p == nullptr) return;
#ifdef HANDDB_HUGE_PAGES_PLAIN_BLOCKS
  std::free(p);
  return;
#endif
  Chunks& s = State();
  std::lock_guard<std::mutex> lock(s.mutex);
  char* c = static_cast<char*>(p);
  for (size_t i = 0; i < s.chunks.size(); ++i) {
    Chunk& chunk = s.chunks[i];
    if (c < chunk.base || c >= chunk.base + chunk.size) continue;
    if (--chunk.live > 0) return;
    if (static_cast<int>(i) == s.current) {
      chunk.used = 0;  // kept for the next blocks
      return;
    }
    ::munmap(chunk.base, chunk.size);
    s.chunks.erase(s.chunks.begin() + static_cast<std::ptrdiff_t>(i));
    if (s.current > static_cast<int>(i)) --s.current;
    return;
  }
}

}  // namespace handdb
