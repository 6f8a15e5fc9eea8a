// A read-only memory mapping of a whole regular file: RAII (unmapped on destruction), move-only.
// An empty file maps to an empty span.
//
// A file truncated or rewritten in place while mapped makes the next read of a page past its new
// end a SIGBUS. Every mapping is listed in a fixed, lock-free registry, and a SIGBUS handler
// (installed with the first mapping) that finds the faulting address in it writes
// "handdb: FILE: changed or truncated while being read" to stderr and exits with status 1; a
// SIGBUS at an address it does not know goes to the previous handler (the default: a core dump).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>

#include "base/status.h"

namespace handdb {

class MappedFile {
 public:
  // madvise hints.
  enum class Advice {
    kNormal,
    kSequential,  // read ahead aggressively, drop pages behind
    kDontNeed,    // drop these pages now (they fault back in from the file if touched again)
  };

  // Errors name the path: kNotFound when it does not exist; kIoError when it cannot be opened or
  // stat'ed, is not a regular file, or cannot be mapped (with the size and errno text).
  // `advice` applies to the whole file.
  static Result<MappedFile> Open(const std::filesystem::path& path,
                                 Advice advice = Advice::kNormal);

  MappedFile() = default;
  ~MappedFile();
  MappedFile(MappedFile&& other) noexcept;
  MappedFile& operator=(MappedFile&& other) noexcept;
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;

  std::span<const uint8_t> bytes() const { return {static_cast<const uint8_t*>(map_), size_}; }
  size_t size() const { return size_; }
  // A hint for bytes [begin, min(end, size())); `begin` is a multiple of the 4096-byte page. No-op
  // on an empty mapping or an empty range.
  void Advise(uint64_t begin, uint64_t end, Advice advice) const;

 private:
  void Reset();

  void* map_ = nullptr;
  size_t size_ = 0;
  int registry_slot_ = -1;  // -1: not listed (the registry was full)
};

}  // namespace handdb
