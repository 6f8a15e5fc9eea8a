#include "format/shard_layout.h"

#include <fcntl.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <sstream>

#include "base/hex.h"

namespace handdb::shard {
namespace {

std::string Quote(const std::string& s) { return "'" + s + "'"; }

// Reports a region of padding that must be zero, by its first non-zero byte.
void CheckZeroRegion(const uint8_t* base,
                     uint64_t begin,
                     uint64_t end,
                     const std::string& where,
                     ProblemList* problems) {
  for (uint64_t o = begin; o < end; ++o) {
    if (base[o] != 0) {
      uint64_t nonzero = 0;
      for (uint64_t k = o; k < end; ++k) nonzero += base[k] != 0;
      std::ostringstream os;
      os << where << ": byte is " << HexPrefixed(base[o]) << ", expected 0 (" << nonzero
         << " non-zero byte(s) in [" << begin << ", " << end << "))";
      problems->Add("padding", StatusCode::kNonZeroReserved, o, os.str());
      return;
    }
  }
}

}  // namespace

uint64_t Checksum(const void* data, size_t size) { return XXH3_64bits(data, size); }

std::string ChecksumHex(uint64_t checksum) { return Hex64(checksum); }

StreamingChecksum::StreamingChecksum() : state_(XXH3_createState()) {
  THROW_CHECK(state_ != nullptr);
  Reset();
}
StreamingChecksum::~StreamingChecksum() { XXH3_freeState(static_cast<XXH3_state_t*>(state_)); }
void StreamingChecksum::Reset() { XXH3_64bits_reset(static_cast<XXH3_state_t*>(state_)); }
void StreamingChecksum::Update(const void* data, size_t size) {
  XXH3_64bits_update(static_cast<XXH3_state_t*>(state_), data, size);
}
uint64_t StreamingChecksum::Digest() const {
  return XXH3_64bits_digest(static_cast<const XXH3_state_t*>(state_));
}

Result<uint64_t> FileChecksum(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const StatusCode code = errno == ENOENT ? StatusCode::kNotFound : StatusCode::kIoError;
    return Status(code, path + ": cannot open: " + std::strerror(errno));
  }
  ::posix_fadvise(fd, 0, 0, POSIX_FADV_SEQUENTIAL);
  StreamingChecksum hash;
  std::vector<uint8_t> buf(1 << 20);
  uint64_t offset = 0;
  while (true) {
    ssize_t n = ::pread(fd, buf.data(), buf.size(), static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      Status s(
          StatusCode::kIoError,
          path + ": read failed at offset " + std::to_string(offset) + ": " + std::strerror(errno));
      ::close(fd);
      return s;
    }
    if (n == 0) break;
    hash.Update(buf.data(), static_cast<size_t>(n));
    offset += static_cast<uint64_t>(n);
  }
  ::close(fd);
  return hash.Digest();
}

RawHeader ParseHeader(std::span<const uint8_t> bytes) {
  THROW_CHECK_GE(bytes.size(), kHeaderSize);
  const uint8_t* b = bytes.data();
  RawHeader h;
  std::memcpy(h.magic.data(), b + kOffMagic, 8);
  h.version_major = Load<uint16_t>(b + kOffVersionMajor);
  h.version_minor = Load<uint16_t>(b + kOffVersionMinor);
  h.header_size = Load<uint32_t>(b + kOffHeaderSize);
  h.required_features = Load<uint64_t>(b + kOffRequiredFeatures);
  h.optional_features = Load<uint64_t>(b + kOffOptionalFeatures);
  h.file_size = Load<uint64_t>(b + kOffFileSize);
  h.num_views = Load<uint64_t>(b + kOffNumViews);
  h.num_points = Load<uint64_t>(b + kOffNumPoints);
  h.section_table_offset = Load<uint64_t>(b + kOffSectionTableOffset);
  h.section_count = Load<uint32_t>(b + kOffSectionCount);
  h.section_entry_size = Load<uint32_t>(b + kOffSectionEntrySize);
  h.section_table_checksum = Load<uint64_t>(b + kOffSectionTableChecksum);
  if (h.header_size >= kOffHeaderReserved + 8 && h.header_size <= bytes.size()) {
    h.header_checksum = Load<uint64_t>(b + h.header_size - 8);
  }
  return h;
}

uint64_t HeaderChecksum(std::span<const uint8_t> header_bytes) {
  THROW_CHECK_GE(header_bytes.size(), 8u);
  return Checksum(header_bytes.data(), header_bytes.size() - 8);
}

void SerializeHeader(const RawHeader& h, std::span<uint8_t> out) {
  THROW_CHECK_EQ(h.header_size, kHeaderSize);
  THROW_CHECK_GE(out.size(), kHeaderSize);
  uint8_t* b = out.data();
  std::memset(b, 0, kHeaderSize);
  std::memcpy(b + kOffMagic, h.magic.data(), 8);
  Store<uint16_t>(b + kOffVersionMajor, h.version_major);
  Store<uint16_t>(b + kOffVersionMinor, h.version_minor);
  Store<uint32_t>(b + kOffHeaderSize, h.header_size);
  Store<uint64_t>(b + kOffRequiredFeatures, h.required_features);
  Store<uint64_t>(b + kOffOptionalFeatures, h.optional_features);
  Store<uint64_t>(b + kOffFileSize, h.file_size);
  Store<uint64_t>(b + kOffNumViews, h.num_views);
  Store<uint64_t>(b + kOffNumPoints, h.num_points);
  Store<uint64_t>(b + kOffSectionTableOffset, h.section_table_offset);
  Store<uint32_t>(b + kOffSectionCount, h.section_count);
  Store<uint32_t>(b + kOffSectionEntrySize, h.section_entry_size);
  Store<uint64_t>(b + kOffSectionTableChecksum, h.section_table_checksum);
  Store<uint64_t>(b + kHeaderSize - 8, HeaderChecksum(std::span<const uint8_t>(b, kHeaderSize)));
}

RawSection ParseSection(const uint8_t* e) {
  RawSection s;
  s.type = Load<uint32_t>(e + kSecOffType);
  s.flags = Load<uint32_t>(e + kSecOffFlags);
  s.offset = Load<uint64_t>(e + kSecOffOffset);
  s.size = Load<uint64_t>(e + kSecOffSize);
  s.count = Load<uint64_t>(e + kSecOffCount);
  s.element_size = Load<uint32_t>(e + kSecOffElementSize);
  s.reserved = Load<uint32_t>(e + kSecOffReserved);
  s.checksum = Load<uint64_t>(e + kSecOffChecksum);
  return s;
}

void SerializeSection(const RawSection& s, uint8_t* e) {
  std::memset(e, 0, kSectionEntrySize);
  Store<uint32_t>(e + kSecOffType, s.type);
  Store<uint32_t>(e + kSecOffFlags, s.flags);
  Store<uint64_t>(e + kSecOffOffset, s.offset);
  Store<uint64_t>(e + kSecOffSize, s.size);
  Store<uint64_t>(e + kSecOffCount, s.count);
  Store<uint32_t>(e + kSecOffElementSize, s.element_size);
  Store<uint32_t>(e + kSecOffReserved, s.reserved);
  Store<uint64_t>(e + kSecOffChecksum, s.checksum);
}

std::string SectionName(uint32_t type) {
  switch (type) {
    case kSectionMetadata:
      return "metadata";
    case kSectionViews:
      return "views";
    case kSectionPoints:
      return "points";
    default:
      return "unknown(" + HexPrefixed(type) + ")";
  }
}

bool ProblemList::Admit(const char* check) {
  if (stop_at_first_ && !problems_.empty()) return false;
  size_t& n = per_check_[check];
  ++n;
  if (max_per_check_ != 0 && n > max_per_check_) {
    ++suppressed_;
    return false;
  }
  return true;
}

void ProblemList::Add(const char* check,
                      StatusCode code,
                      uint64_t offset,
                      const std::string& what) {
  if (!Admit(check)) return;
  problems_.push_back({code, offset, file_ + ": offset " + std::to_string(offset) + ": " + what});
}

void ProblemList::AddFileLevel(const char* check, StatusCode code, const std::string& what) {
  if (!Admit(check)) return;
  problems_.push_back({code, 0, file_ + ": " + what});
}

Status ProblemList::FirstStatus() const {
  if (problems_.empty()) return Status::Ok();
  return Status(problems_.front().code, problems_.front().message);
}

Layout CheckLayout(std::span<const uint8_t> bytes, ProblemList* problems) {
  Layout layout;
  const uint8_t* b = bytes.data();
  const uint64_t n = bytes.size();

  // --- Header: fatal problems first (nothing after them can be interpreted).
  const size_t magic_len = static_cast<size_t>(std::min<uint64_t>(n, 8));
  if (magic_len == 0 || std::memcmp(b, kMagic.data(), magic_len) != 0) {
    if (magic_len == 0) {
      problems->Add("size", StatusCode::kTruncated, 0, "file is empty (0 bytes)");
    } else {
      problems->Add("magic",
                    StatusCode::kBadMagic,
                    0,
                    "leading magic is [" + HexBytes(b, magic_len, " ") + "], expected [" +
                        HexBytes(kMagic.data(), 8, " ") + "]: not a handdb shard");
    }
    return layout;
  }
  if (n < kMinFileSize) {
    problems->Add("size",
                  StatusCode::kTruncated,
                  0,
                  "file is " + std::to_string(n) + " bytes, smaller than the smallest shard (" +
                      std::to_string(kMinFileSize) + " bytes: header + footer)");
    return layout;
  }
  RawHeader h = ParseHeader(bytes);
  layout.header = h;
  if (h.version_major != kVersionMajor) {
    problems->Add("version",
                  StatusCode::kUnsupportedVersion,
                  kOffVersionMajor,
                  "format version " + std::to_string(h.version_major) + "." +
                      std::to_string(h.version_minor) + ", this reader supports major version " +
                      std::to_string(kVersionMajor));
    return layout;
  }
  if (h.header_size < kHeaderSize || h.header_size % 8 != 0 || h.header_size > n - kFooterSize) {
    problems->Add("header",
                  StatusCode::kBadLayout,
                  kOffHeaderSize,
                  "header_size is " + std::to_string(h.header_size) +
                      ", expected a multiple of 8, at least " + std::to_string(kHeaderSize) +
                      " and leaving room for the footer in a " + std::to_string(n) + "-byte file");
    return layout;
  }
  const uint64_t header_checksum =
      HeaderChecksum(std::span<const uint8_t>(b, static_cast<size_t>(h.header_size)));
  if (header_checksum != h.header_checksum) {
    problems->Add("checksum",
                  StatusCode::kChecksumMismatch,
                  h.header_size - 8,
                  "header checksum stored " + ChecksumHex(h.header_checksum) + ", computed " +
                      ChecksumHex(header_checksum));
    if (problems->done()) return layout;
  }
  if (h.file_size != n) {
    if (h.file_size > n) {
      problems->Add("size",
                    StatusCode::kTruncated,
                    kOffFileSize,
                    "file is " + std::to_string(n) + " bytes but its header says file_size " +
                        std::to_string(h.file_size) + " (truncated)");
    } else {
      problems->Add("size",
                    StatusCode::kSizeMismatch,
                    kOffFileSize,
                    "file is " + std::to_string(n) + " bytes but its header says file_size " +
                        std::to_string(h.file_size) + " (trailing bytes)");
    }
    if (problems->done()) return layout;
  }
  const bool know_minor = h.version_minor <= kVersionMinor;
  if ((h.required_features & ~kKnownRequiredFeatures) != 0) {
    problems->Add("features",
                  StatusCode::kUnknownRequiredFeature,
                  kOffRequiredFeatures,
                  "required_features " + HexPrefixed(h.required_features) +
                      " has bits unknown to this " + "reader (" +
                      HexPrefixed(h.required_features & ~kKnownRequiredFeatures) + ")");
    if (problems->done()) return layout;
  }
  if (know_minor) {
    CheckZeroRegion(b, kOffHeaderReserved, h.header_size - 8, "reserved header bytes", problems);
    if (problems->done()) return layout;
  }

  // --- Footer.
  const uint64_t footer_at = n - kFooterSize;
  const uint64_t footer_size = Load<uint64_t>(b + footer_at);
  if (std::memcmp(b + footer_at + 8, kMagic.data(), 8) != 0) {
    problems->Add("footer",
                  StatusCode::kBadMagic,
                  footer_at + 8,
                  "trailing magic is [" + HexBytes(b + footer_at + 8, 8, " ") + "], expected [" +
                      HexBytes(kMagic.data(), 8, " ") + "] (truncated or overwritten end)");
    if (problems->done()) return layout;
  }
  if (footer_size != n) {
    problems->Add("footer",
                  footer_size > n ? StatusCode::kTruncated : StatusCode::kSizeMismatch,
                  footer_at,
                  "footer says file_size " + std::to_string(footer_size) + ", file is " +
                      std::to_string(n) + " bytes");
    if (problems->done()) return layout;
  }

  // --- Section table.
  if (h.section_table_offset != h.header_size) {
    problems->Add("table",
                  StatusCode::kBadLayout,
                  kOffSectionTableOffset,
                  "section_table_offset is " + std::to_string(h.section_table_offset) +
                      ", expected header_size " + std::to_string(h.header_size));
    return layout;
  }
  if (h.section_entry_size < kSectionEntrySize || h.section_entry_size % 8 != 0 ||
      (know_minor && h.section_entry_size != kSectionEntrySize)) {
    problems->Add("table",
                  StatusCode::kBadLayout,
                  kOffSectionEntrySize,
                  "section_entry_size is " + std::to_string(h.section_entry_size) + ", expected " +
                      std::to_string(kSectionEntrySize));
    return layout;
  }
  if (h.section_count > kMaxSections) {
    problems->Add("table",
                  StatusCode::kOutOfRange,
                  kOffSectionCount,
                  "section_count is " + std::to_string(h.section_count) + ", more than " +
                      std::to_string(kMaxSections));
    return layout;
  }
  const uint64_t table_bytes = uint64_t{h.section_count} * h.section_entry_size;
  const uint64_t table_end = h.section_table_offset + table_bytes;
  if (table_end > footer_at) {
    problems->Add("table",
                  StatusCode::kTruncated,
                  h.section_table_offset,
                  "section table of " + std::to_string(h.section_count) + " entries ends at " +
                      std::to_string(table_end) + ", past the footer at " +
                      std::to_string(footer_at));
    return layout;
  }
  const uint64_t table_checksum = Checksum(b + h.section_table_offset, table_bytes);
  if (table_checksum != h.section_table_checksum) {
    problems->Add("checksum",
                  StatusCode::kChecksumMismatch,
                  kOffSectionTableChecksum,
                  "section table checksum stored " + ChecksumHex(h.section_table_checksum) +
                      ", computed " + ChecksumHex(table_checksum));
    if (problems->done()) return layout;
  }

  bool bounds_ok = true;
  uint64_t prev_end = table_end;
  std::string prev_name = "section table";
  for (uint32_t i = 0; i < h.section_count; ++i) {
    const uint64_t entry_at = h.section_table_offset + uint64_t{i} * h.section_entry_size;
    const RawSection s = ParseSection(b + entry_at);
    layout.sections.push_back(s);
    const std::string name = SectionName(s.type);
    const std::string label = "section " + std::to_string(i) + " " + Quote(name);
    if (know_minor && (s.flags & ~kKnownSectionFlags) != 0) {
      problems->Add("reserved",
                    StatusCode::kNonZeroReserved,
                    entry_at + kSecOffFlags,
                    label + ": flags " + HexPrefixed(s.flags) + " has reserved bits set");
    }
    if (s.reserved != 0) {
      problems->Add("reserved",
                    StatusCode::kNonZeroReserved,
                    entry_at + kSecOffReserved,
                    label + ": reserved field is " + HexPrefixed(s.reserved) + ", expected 0");
    }
    const uint64_t expected = AlignUp(prev_end);
    if (s.offset != expected) {
      problems->Add("layout",
                    StatusCode::kBadLayout,
                    entry_at + kSecOffOffset,
                    label + ": offset is " + std::to_string(s.offset) + ", expected " +
                        std::to_string(expected) + " (the first 64-byte boundary after the " +
                        prev_name + ", which ends at " + std::to_string(prev_end) + ")");
      bounds_ok = false;
    }
    if (s.offset > footer_at || s.size > footer_at - s.offset) {
      problems->Add("bounds",
                    StatusCode::kTruncated,
                    entry_at + kSecOffSize,
                    label + ": [" + std::to_string(s.offset) + ", +" + std::to_string(s.size) +
                        ") extends past the footer at " + std::to_string(footer_at));
      bounds_ok = false;
      if (problems->done()) return layout;
      break;  // nothing after this entry can be placed
    }
    if (s.element_size == 0 || s.count > s.size / s.element_size ||
        s.count * s.element_size != s.size) {
      problems->Add("size",
                    StatusCode::kSizeMismatch,
                    entry_at + kSecOffCount,
                    label + ": count " + std::to_string(s.count) + " x element_size " +
                        std::to_string(s.element_size) + " does not equal size " +
                        std::to_string(s.size));
      bounds_ok = false;
    }
    if (s.offset == expected && prev_end <= s.offset) {
      CheckZeroRegion(b, prev_end, s.offset, "padding before " + label, problems);
    }
    int* slot = nullptr;
    uint32_t want_element = 0;
    switch (s.type) {
      case kSectionMetadata:
        slot = &layout.metadata;
        want_element = 1;
        break;
      case kSectionViews:
        slot = &layout.views;
        want_element = kViewRecordSize;
        break;
      case kSectionPoints:
        slot = &layout.points;
        want_element = kPointSize;
        break;
      default:
        if ((s.flags & kSectionFlagRequired) != 0) {
          problems->Add("features",
                        StatusCode::kUnknownRequiredFeature,
                        entry_at + kSecOffType,
                        label + ": unknown section type " + HexPrefixed(s.type) +
                            " is marked required (flags " + HexPrefixed(s.flags) + ")");
        }
        break;
    }
    if (slot != nullptr) {
      if (*slot >= 0) {
        problems->Add("layout",
                      StatusCode::kBadLayout,
                      entry_at + kSecOffType,
                      label + ": a second " + Quote(name) + " section (the first is section " +
                          std::to_string(*slot) + ")");
        bounds_ok = false;
      } else {
        *slot = static_cast<int>(i);
      }
      const bool element_ok = s.type == kSectionViews && !know_minor
                                  ? (s.element_size >= want_element && s.element_size % 8 == 0)
                                  : s.element_size == want_element;
      if (!element_ok) {
        problems->Add("size",
                      StatusCode::kSizeMismatch,
                      entry_at + kSecOffElementSize,
                      label + ": element_size is " + std::to_string(s.element_size) +
                          ", expected " + std::to_string(want_element));
        bounds_ok = false;
      }
    }
    if (problems->done()) return layout;
    prev_end = s.offset + s.size;
    prev_name = label;
  }
  if (bounds_ok) {
    const uint64_t expected_footer = AlignUp(prev_end);
    if (expected_footer != footer_at) {
      problems->Add("layout",
                    StatusCode::kBadLayout,
                    footer_at,
                    "footer is at " + std::to_string(footer_at) + ", expected " +
                        std::to_string(expected_footer) + " (the first 64-byte boundary after " +
                        prev_name + ", which ends at " + std::to_string(prev_end) + ")");
      bounds_ok = false;
    } else {
      CheckZeroRegion(b, prev_end, footer_at, "padding before the footer", problems);
    }
  }
  for (auto [slot, type] : {std::pair{layout.metadata, kSectionMetadata},
                            std::pair{layout.views, kSectionViews},
                            std::pair{layout.points, kSectionPoints}}) {
    if (slot < 0 && bounds_ok) {
      problems->Add("layout",
                    StatusCode::kBadLayout,
                    kOffSectionCount,
                    "no " + Quote(SectionName(type)) + " section in the section table (" +
                        std::to_string(h.section_count) + " entries)");
      bounds_ok = false;
    }
  }
  if (problems->done()) return layout;
  if (layout.views >= 0 && layout.sections[layout.views].count != h.num_views) {
    problems->Add("counts",
                  StatusCode::kSizeMismatch,
                  kOffNumViews,
                  "header num_views is " + std::to_string(h.num_views) +
                      " but the views section holds " +
                      std::to_string(layout.sections[layout.views].count));
  }
  if (layout.points >= 0 && layout.sections[layout.points].count != h.num_points) {
    problems->Add("counts",
                  StatusCode::kSizeMismatch,
                  kOffNumPoints,
                  "header num_points is " + std::to_string(h.num_points) +
                      " but the points section holds " +
                      std::to_string(layout.sections[layout.points].count));
  }
  if (!bounds_ok || layout.metadata < 0 || layout.views < 0 || layout.points < 0) return layout;
  layout.structure_ok = true;
  if (problems->done()) return layout;

  // --- Every view's point range, before anyone takes a span of it.
  const RawSection& vs = layout.sections[layout.views];
  const RawSection& ps = layout.sections[layout.points];
  layout.view_stride = vs.element_size;
  bool views_ok = true;
  uint64_t running = 0;
  for (uint64_t i = 0; i < vs.count; ++i) {
    const uint64_t at = vs.offset + i * vs.element_size;
    const uint8_t* rec = b + at;
    const uint32_t flags = Load<uint32_t>(rec + kViewOffFlags);
    if (flags != 0 && know_minor) {
      problems->Add("reserved",
                    StatusCode::kNonZeroReserved,
                    at + kViewOffFlags,
                    "view " + std::to_string(i) + ": reserved flags are " + HexPrefixed(flags) +
                        ", expected 0");
    }
    const uint64_t off = Load<uint64_t>(rec + kViewOffPointOffset);
    const uint32_t cnt = Load<uint32_t>(rec + kViewOffPointCount);
    if (off > ps.count || cnt > ps.count - off) {
      problems->Add("view-range",
                    StatusCode::kOutOfRange,
                    at + kViewOffPointOffset,
                    "view " + std::to_string(i) + ": points [" + std::to_string(off) + ", +" +
                        std::to_string(cnt) + ") lie outside the points section (" +
                        std::to_string(ps.count) + " points)");
      views_ok = false;
    } else if (off != running) {
      problems->Add("view-range",
                    StatusCode::kBadLayout,
                    at + kViewOffPointOffset,
                    "view " + std::to_string(i) + ": point_offset is " + std::to_string(off) +
                        ", expected " + std::to_string(running) +
                        " (views must cover the points in order without holes or overlaps)");
      views_ok = false;
    }
    if (problems->done()) return layout;
    running = (off <= ps.count && cnt <= ps.count - off) ? off + cnt : running + cnt;
  }
  if (running != ps.count) {
    problems->Add("view-range",
                  StatusCode::kBadLayout,
                  vs.offset,
                  "views cover " + std::to_string(running) + " points, the points section holds " +
                      std::to_string(ps.count));
    views_ok = false;
  }
  layout.views_ok = views_ok;
  return layout;
}

void CheckSectionChecksums(std::span<const uint8_t> bytes,
                           const Layout& layout,
                           ProblemList* problems) {
  const uint8_t* b = bytes.data();
  const RawHeader& h = layout.header;
  if (h.header_size < kHeaderSize || h.header_size > bytes.size()) return;
  const uint64_t header_checksum =
      HeaderChecksum(std::span<const uint8_t>(b, static_cast<size_t>(h.header_size)));
  if (header_checksum != h.header_checksum) {
    problems->Add("checksum",
                  StatusCode::kChecksumMismatch,
                  h.header_size - 8,
                  "header checksum stored " + ChecksumHex(h.header_checksum) + ", computed " +
                      ChecksumHex(header_checksum));
    if (problems->done()) return;
  }
  const uint64_t n = bytes.size();
  for (size_t i = 0; i < layout.sections.size(); ++i) {
    const RawSection& s = layout.sections[i];
    if (s.offset > n || s.size > n - s.offset) continue;  // reported by CheckLayout
    const uint64_t computed = Checksum(b + s.offset, s.size);
    if (computed != s.checksum) {
      problems->Add("checksum",
                    StatusCode::kChecksumMismatch,
                    s.offset,
                    "section " + std::to_string(i) + " " + Quote(SectionName(s.type)) + " [" +
                        std::to_string(s.offset) + ", +" + std::to_string(s.size) +
                        "): checksum stored " + ChecksumHex(s.checksum) + ", computed " +
                        ChecksumHex(computed));
      if (problems->done()) return;
    }
  }
}

ViewLabel DecodeViewLabel(const uint8_t* r) {
  ViewLabel l;
  l.render_id = Load<uint32_t>(r + kViewOffRenderId);
  l.shape_id = Load<uint32_t>(r + kViewOffShapeId);
  l.dir_id = Load<uint32_t>(r + kViewOffDirId);
  l.flags = Load<uint32_t>(r + kViewOffFlags);
  std::memcpy(l.joint_angles.data(), r + kViewOffJointAngles, sizeof(float) * kNumJointAngles);
  std::memcpy(l.view_direction.data(), r + kViewOffViewDirection, sizeof(float) * 3);
  l.view_theta = Load<float>(r + kViewOffViewTheta);
  l.view_phi = Load<float>(r + kViewOffViewPhi);
  l.camera_roll = Load<float>(r + kViewOffCameraRoll);
  for (int k = 0; k < kNumKeypoints; ++k) {
    std::memcpy(l.keypoints[k].data(), r + kViewOffKeypoints + 12 * k, 12);
  }
  l.source_diameter_px = Load<float>(r + kViewOffSourceDiameter);
  l.scale = Load<float>(r + kViewOffScale);
  std::memcpy(l.source_centre_px.data(), r + kViewOffSourceCentre, 8);
  return l;
}

void EncodeViewRecord(const ViewLabel& l, uint64_t point_offset, uint32_t point_count, uint8_t* r) {
  std::memset(r, 0, kViewRecordSize);
  Store<uint32_t>(r + kViewOffRenderId, l.render_id);
  Store<uint32_t>(r + kViewOffShapeId, l.shape_id);
  Store<uint32_t>(r + kViewOffDirId, l.dir_id);
  Store<uint32_t>(r + kViewOffFlags, l.flags);
  std::memcpy(r + kViewOffJointAngles, l.joint_angles.data(), sizeof(float) * kNumJointAngles);
  std::memcpy(r + kViewOffViewDirection, l.view_direction.data(), sizeof(float) * 3);
  Store<float>(r + kViewOffViewTheta, l.view_theta);
  Store<float>(r + kViewOffViewPhi, l.view_phi);
  Store<float>(r + kViewOffCameraRoll, l.camera_roll);
  for (int k = 0; k < kNumKeypoints; ++k) {
    std::memcpy(r + kViewOffKeypoints + 12 * k, l.keypoints[k].data(), 12);
  }
  Store<float>(r + kViewOffSourceDiameter, l.source_diameter_px);
  Store<float>(r + kViewOffScale, l.scale);
  std::memcpy(r + kViewOffSourceCentre, l.source_centre_px.data(), 8);
  Store<uint32_t>(r + kViewOffPointCount, point_count);
  Store<uint64_t>(r + kViewOffPointOffset, point_offset);
}

bool RewriteChecksums(std::span<uint8_t> bytes) {
  const uint64_t n = bytes.size();
  if (n < kMinFileSize) return false;
  uint8_t* b = bytes.data();
  const RawHeader h = ParseHeader(bytes);
  if (h.header_size < kHeaderSize || h.header_size > n ||
      h.section_entry_size < kSectionEntrySize || h.section_count > kMaxSections ||
      h.section_table_offset > n) {
    return false;
  }
  const uint64_t table_bytes = uint64_t{h.section_count} * h.section_entry_size;
  if (table_bytes > n - h.section_table_offset) return false;
  for (uint32_t i = 0; i < h.section_count; ++i) {
    uint8_t* e = b + h.section_table_offset + uint64_t{i} * h.section_entry_size;
    const RawSection s = ParseSection(e);
    if (s.offset > n || s.size > n - s.offset) return false;
    Store<uint64_t>(e + kSecOffChecksum, Checksum(b + s.offset, s.size));
  }
  Store<uint64_t>(b + kOffSectionTableChecksum, Checksum(b + h.section_table_offset, table_bytes));
  Store<uint64_t>(b + h.header_size - 8,
                  HeaderChecksum(std::span<const uint8_t>(b, static_cast<size_t>(h.header_size))));
  return true;
}

}  // namespace handdb::shard
