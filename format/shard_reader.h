// Reads one shard. Open() memory-maps the file read-only and runs the cheap checks (header,
// section table, footer, view-table bounds); VerifyChecksums() hashes every section on demand.
// All accessors are const and safe from many threads; spans point into the mapping (zero-copy)
// and live as long as the reader.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "format/view.h"

namespace handdb {

struct ViewPointsExtent;  // format/point_codec.h (internal to the format library)

struct SectionInfo {
  uint32_t type = 0;
  uint32_t flags = 0;
  uint64_t offset = 0;
  uint64_t size = 0;
  uint64_t count = 0;
  uint32_t element_size = 0;
  uint64_t checksum = 0;
  std::string name;  // "metadata", "views", "points", or "unknown(0x...)"
};

struct ShardHeaderInfo {
  uint16_t version_major = 0;
  uint16_t version_minor = 0;
  uint64_t required_features = 0;
  uint64_t optional_features = 0;
  uint64_t num_views = 0;
  uint64_t num_points = 0;
  uint64_t file_size = 0;
};

struct ScanOptions {
  // Hash the views and points sections while scanning (plus the small sections at the end), so a
  // full verification costs one pass instead of two; a mismatch is returned after the last view.
  bool verify_checksums = false;
};

class ShardReader {
 public:
  using ViewCallback =
      std::function<Status(size_t index, const ViewLabel& label, std::span<const PointQ> points)>;

  ~ShardReader();
  ShardReader(const ShardReader&) = delete;
  ShardReader& operator=(const ShardReader&) = delete;
  ShardReader(ShardReader&&) noexcept;
  ShardReader& operator=(ShardReader&&) noexcept;

  // mmap a file. Errors name the path, the offset and the raw values.
  static Result<ShardReader> Open(const std::filesystem::path& path);
  // Parse bytes already in memory (tests, fuzzing). `bytes` must outlive the reader;
  // `name` is used in messages.
  static Result<ShardReader> FromMemory(std::span<const uint8_t> bytes, std::string name);

  // Hash every section and the header; kChecksumMismatch names the section.
  Status VerifyChecksums() const;

  const ShardHeaderInfo& header() const;
  const std::vector<SectionInfo>& sections() const;
  std::string_view metadata_json() const;
  const std::string& name() const;

  size_t num_views() const;
  ViewLabel label(size_t i) const;  // bounds-checked (THROW_CHECK)
  // A plain shard's points of view i, zero-copy. A coded shard (coded()) has no stored points:
  // points() and point_offset() THROW_CHECK, all_points() is empty; use DecodePoints().
  std::span<const PointQ> points(size_t i) const;  // bounds-checked, zero-copy
  std::span<const PointQ> all_points() const;      // the whole flat array
  uint64_t point_offset(size_t i) const;           // index into all_points()

  // True for a v1.2 shard with coded views (docs/format.md section 10): points and coarse
  // fields are stored as codes and decoded on demand (~10 us per view each).
  bool coded() const;
  // Number of points of view i (the record's count; for a coded shard, what its code decodes to).
  uint32_t point_count(size_t i) const;
  // View i's points into *out (replaced): a copy for a plain shard, decoded for a coded one.
  // A code that does not decode, or decodes to another count than its record's, is kBadLayout /
  // kTruncated / kSizeMismatch naming the file, the view and the byte offset.
  Status DecodePoints(size_t i, std::vector<PointQ>* out) const;
  // For a coded shard, what view i's point code's header says (format/point_codec.h,
  // PeekViewPoints: count, sortedness and a bound on |x|, |y| for a lattice-mode code), with
  // errors named like DecodePoints'; for a plain shard extent->peeked is false.
  Status PeekPoints(size_t i, ViewPointsExtent* extent) const;
  // View i's coarse field (shard::kCoarseFieldSize bytes) into `out`: copied from the v1.1
  // section or decoded from field_codes; kNotFound for a plain shard without coarse fields.
  Status DecodeCoarseField(size_t i, uint8_t* out) const;
  // The codes themselves (empty spans for a plain shard), for tools and the validator.
  std::span<const uint8_t> point_code(size_t i) const;
  std::span<const uint8_t> field_code(size_t i) const;

  // Sequential streaming mode: calls fn for every view in file order (a coded shard's points
  // decoded into a buffer that lives until fn returns), advising the kernel that
  // the views and points are read sequentially (MADV_SEQUENTIAL: aggressive read-ahead, pages
  // dropped behind), so a scan of a shard larger than the page cache streams at disk speed.
  // Stops at fn's first error.
  Status ScanViews(const ViewCallback& fn, const ScanOptions& options = {}) const;

  // The v1.1 coarse-fields section (format/coarse_field.h): num_views() fields of
  // shard::kCoarseFieldSize bytes in view order, zero-copy; empty for a shard without one (and
  // for a coded shard, whose fields DecodeCoarseField() decodes).
  std::span<const uint8_t> coarse_fields() const;
  bool has_coarse_fields() const;
  // View i's field, or nullptr without the section. Bounds-checked (THROW_CHECK).
  const uint8_t* coarse_field(size_t i) const;

  // The whole file (the mapping or the caller's memory).
  std::span<const uint8_t> bytes() const;

  // For a caller that has taken what it needs from the view table (the query's Database keeps
  // each view's point span): drops the table's mapped pages from this process's resident set.
  // The open checks read every record, and the table is ~15% of a shard (400 of ~2,640 bytes per
  // view) that a search reads only for its top-k labels. MADV_DONTNEED on this read-only file
  // mapping: nothing is lost, a later label() faults its page back in from the page cache (with
  // the kernel's fault-around, 32-64 KB of the table at a time).
  // No-op for readers over caller memory.
  void ReleaseViewTablePages() const;
  // The same for the coarse-fields section, for a caller that keeps its own copy of the fields
  // (the search's cell-major one, query/coarse_bound.h): coarse_field() still works afterwards.
  void ReleaseCoarseFieldPages() const;
  // The same for a coded shard's point codes, for a caller that has decoded what it needs (the
  // query's Database, after the open's pass over every view); no-op for a plain shard.
  void ReleasePointCodePages() const;

 private:
  struct Impl;
  explicit ShardReader(std::unique_ptr<Impl> impl);
  static Result<ShardReader> Init(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace handdb
