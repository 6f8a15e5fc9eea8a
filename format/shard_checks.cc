#include "format/shard_checks.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <utility>

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
  problems_.push_back(
      {code, offset, file_ + ": offset " + std::to_string(offset) + ": " + what, what});
}

void ProblemList::AddFileLevel(const char* check, StatusCode code, const std::string& what) {
  if (!Admit(check)) return;
  problems_.push_back({code, 0, file_ + ": " + what, what});
}

Status ProblemList::FirstStatus() const {
  if (problems_.empty()) return Status::Ok();
  return Status(problems_.front().code, problems_.front().message);
}

namespace {

// The layout checks, in the order CheckLayout chains them. Each takes the scan state, adds at most
// its own kind of problem, and returns false when checking must stop: a fatal problem (nothing
// after it can be interpreted) or a stop-at-first list that has its problem.
struct LayoutScan {
  const uint8_t* b = nullptr;
  uint64_t n = 0;
  ProblemList* problems = nullptr;
  Layout* layout = nullptr;
  bool know_minor = false;  // the minor version is one this reader knows (reserved bits checked)
  uint64_t footer_at = 0;
  uint64_t table_end = 0;
  bool bounds_ok = true;  // section offsets, sizes and uniqueness are consistent
  uint64_t prev_end = 0;  // end of the previous section (or of the table)
  std::string prev_name;
};

bool CheckMagic(LayoutScan& c) {
  const size_t magic_len = static_cast<size_t>(std::min<uint64_t>(c.n, 8));
  if (magic_len != 0 && std::memcmp(c.b, kMagic.data(), magic_len) == 0) return true;
  if (magic_len == 0) {
    c.problems->Add("size", StatusCode::kTruncated, 0, "file is empty (0 bytes)");
  } else {
    c.problems->Add("magic",
                    StatusCode::kBadMagic,
                    0,
                    "leading magic is [" + HexBytes(c.b, magic_len, " ") + "], expected [" +
                        HexBytes(kMagic.data(), 8, " ") + "]: not a handdb shard");
  }
  return false;
}

bool CheckMinimumSize(LayoutScan& c) {
  if (c.n >= kMinFileSize) return true;
  c.problems->Add("size",
                  StatusCode::kTruncated,
                  0,
                  "file is " + std::to_string(c.n) + " bytes, smaller than the smallest shard (" +
                      std::to_string(kMinFileSize) + " bytes: header + footer)");
  return false;
}

bool CheckVersion(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  if (h.version_major == kVersionMajor) return true;
  c.problems->Add("version",
                  StatusCode::kUnsupportedVersion,
                  kOffVersionMajor,
                  "format version " + std::to_string(h.version_major) + "." +
                      std::to_string(h.version_minor) + ", this reader supports major version " +
                      std::to_string(kVersionMajor));
  return false;
}

bool CheckHeaderSize(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  if (h.header_size >= kHeaderSize && h.header_size % 8 == 0 &&
      h.header_size <= c.n - kFooterSize) {
    return true;
  }
  c.problems->Add("header",
                  StatusCode::kBadLayout,
                  kOffHeaderSize,
                  "header_size is " + std::to_string(h.header_size) +
                      ", expected a multiple of 8, at least " + std::to_string(kHeaderSize) +
                      " and leaving room for the footer in a " + std::to_string(c.n) +
                      "-byte file");
  return false;
}

bool CheckHeaderChecksum(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  const uint64_t header_checksum =
      HeaderChecksum(std::span<const uint8_t>(c.b, static_cast<size_t>(h.header_size)));
  if (header_checksum == h.header_checksum) return true;
  c.problems->Add("checksum",
                  StatusCode::kChecksumMismatch,
                  h.header_size - 8,
                  "header checksum stored " + ChecksumHex(h.header_checksum) + ", computed " +
                      ChecksumHex(header_checksum));
  return !c.problems->done();
}

bool CheckFileSize(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  if (h.file_size == c.n) return true;
  if (h.file_size > c.n) {
    c.problems->Add("size",
                    StatusCode::kTruncated,
                    kOffFileSize,
                    "file is " + std::to_string(c.n) + " bytes but its header says file_size " +
                        std::to_string(h.file_size) + " (truncated)");
  } else {
    c.problems->Add("size",
                    StatusCode::kSizeMismatch,
                    kOffFileSize,
                    "file is " + std::to_string(c.n) + " bytes but its header says file_size " +
                        std::to_string(h.file_size) + " (trailing bytes)");
  }
  return !c.problems->done();
}

bool CheckRequiredFeatures(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  if ((h.required_features & ~kKnownRequiredFeatures) == 0) return true;
  c.problems->Add("features",
                  StatusCode::kUnknownRequiredFeature,
                  kOffRequiredFeatures,
                  "required_features " + HexPrefixed(h.required_features) +
                      " has bits unknown to this " + "reader (" +
                      HexPrefixed(h.required_features & ~kKnownRequiredFeatures) + ")");
  return !c.problems->done();
}

bool CheckHeaderReserved(LayoutScan& c) {
  if (!c.know_minor) return true;
  CheckZeroRegion(c.b,
                  kOffHeaderReserved,
                  c.layout->header.header_size - 8,
                  "reserved header bytes",
                  c.problems);
  return !c.problems->done();
}

bool CheckFooterMagic(LayoutScan& c) {
  if (std::memcmp(c.b + c.footer_at + 8, kMagic.data(), 8) == 0) return true;
  c.problems->Add("footer",
                  StatusCode::kBadMagic,
                  c.footer_at + 8,
                  "trailing magic is [" + HexBytes(c.b + c.footer_at + 8, 8, " ") +
                      "], expected [" + HexBytes(kMagic.data(), 8, " ") +
                      "] (truncated or overwritten end)");
  return !c.problems->done();
}

bool CheckFooterSize(LayoutScan& c) {
  const uint64_t footer_size = LoadLittleEndian<uint64_t>(c.b + c.footer_at);
  if (footer_size == c.n) return true;
  c.problems->Add("footer",
                  footer_size > c.n ? StatusCode::kTruncated : StatusCode::kSizeMismatch,
                  c.footer_at,
                  "footer says file_size " + std::to_string(footer_size) + ", file is " +
                      std::to_string(c.n) + " bytes");
  return !c.problems->done();
}

bool CheckTableOffset(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  if (h.section_table_offset == h.header_size) return true;
  c.problems->Add("table",
                  StatusCode::kBadLayout,
                  kOffSectionTableOffset,
                  "section_table_offset is " + std::to_string(h.section_table_offset) +
                      ", expected header_size " + std::to_string(h.header_size));
  return false;
}

bool CheckTableEntrySize(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  if (h.section_entry_size >= kSectionEntrySize && h.section_entry_size % 8 == 0 &&
      !(c.know_minor && h.section_entry_size != kSectionEntrySize)) {
    return true;
  }
  c.problems->Add("table",
                  StatusCode::kBadLayout,
                  kOffSectionEntrySize,
                  "section_entry_size is " + std::to_string(h.section_entry_size) + ", expected " +
                      std::to_string(kSectionEntrySize));
  return false;
}

bool CheckTableCount(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  if (h.section_count <= kMaxSections) return true;
  c.problems->Add("table",
                  StatusCode::kOutOfRange,
                  kOffSectionCount,
                  "section_count is " + std::to_string(h.section_count) + ", more than " +
                      std::to_string(kMaxSections));
  return false;
}

bool CheckTableEnd(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  c.table_end = h.section_table_offset + uint64_t{h.section_count} * h.section_entry_size;
  if (c.table_end <= c.footer_at) return true;
  c.problems->Add("table",
                  StatusCode::kTruncated,
                  h.section_table_offset,
                  "section table of " + std::to_string(h.section_count) + " entries ends at " +
                      std::to_string(c.table_end) + ", past the footer at " +
                      std::to_string(c.footer_at));
  return false;
}

bool CheckTableChecksum(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  const uint64_t table_checksum =
      Checksum(c.b + h.section_table_offset, c.table_end - h.section_table_offset);
  if (table_checksum == h.section_table_checksum) return true;
  c.problems->Add("checksum",
                  StatusCode::kChecksumMismatch,
                  kOffSectionTableChecksum,
                  "section table checksum stored " + ChecksumHex(h.section_table_checksum) +
                      ", computed " + ChecksumHex(table_checksum));
  return !c.problems->done();
}

// Flags with reserved bits and a non-zero reserved field (both reported, checking goes on).
void CheckSectionReserved(LayoutScan& c,
                          const RawSection& s,
                          uint64_t entry_at,
                          const std::string& label) {
  if (c.know_minor && (s.flags & ~kKnownSectionFlags) != 0) {
    c.problems->Add("reserved",
                    StatusCode::kNonZeroReserved,
                    entry_at + kSecOffFlags,
                    label + ": flags " + HexPrefixed(s.flags) + " has reserved bits set");
  }
  if (s.reserved != 0) {
    c.problems->Add("reserved",
                    StatusCode::kNonZeroReserved,
                    entry_at + kSecOffReserved,
                    label + ": reserved field is " + HexPrefixed(s.reserved) + ", expected 0");
  }
}

// The section starts at the first 64-byte boundary after the previous one.
void CheckSectionOffset(LayoutScan& c,
                        const RawSection& s,
                        uint64_t entry_at,
                        const std::string& label) {
  const uint64_t expected = AlignUp(c.prev_end);
  if (s.offset == expected) return;
  c.problems->Add("layout",
                  StatusCode::kBadLayout,
                  entry_at + kSecOffOffset,
                  label + ": offset is " + std::to_string(s.offset) + ", expected " +
                      std::to_string(expected) + " (the first 64-byte boundary after the " +
                      c.prev_name + ", which ends at " + std::to_string(c.prev_end) + ")");
  c.bounds_ok = false;
}

// False when the section extends past the footer (nothing after this entry can be placed).
bool CheckSectionBounds(LayoutScan& c,
                        const RawSection& s,
                        uint64_t entry_at,
                        const std::string& label) {
  if (s.offset <= c.footer_at && s.size <= c.footer_at - s.offset) return true;
  c.problems->Add("bounds",
                  StatusCode::kTruncated,
                  entry_at + kSecOffSize,
                  label + ": [" + std::to_string(s.offset) + ", +" + std::to_string(s.size) +
                      ") extends past the footer at " + std::to_string(c.footer_at));
  c.bounds_ok = false;
  return false;
}

// count x element_size == size.
void CheckSectionSize(LayoutScan& c,
                      const RawSection& s,
                      uint64_t entry_at,
                      const std::string& label) {
  if (s.element_size != 0 && s.count <= s.size / s.element_size &&
      s.count * s.element_size == s.size) {
    return;
  }
  c.problems->Add("size",
                  StatusCode::kSizeMismatch,
                  entry_at + kSecOffCount,
                  label + ": count " + std::to_string(s.count) + " x element_size " +
                      std::to_string(s.element_size) + " does not equal size " +
                      std::to_string(s.size));
  c.bounds_ok = false;
}

// A known type appears once with its element size; an unknown type must not be required.
void CheckSectionType(LayoutScan& c,
                      uint32_t i,
                      const RawSection& s,
                      uint64_t entry_at,
                      const std::string& name,
                      const std::string& label) {
  Layout& layout = *c.layout;
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
    case kSectionCoarseFields:
      slot = &layout.coarse_fields;
      want_element = kCoarseFieldSize;
      break;
    case kSectionPointCodes:
      slot = &layout.point_codes;
      want_element = 1;
      break;
    case kSectionFieldCodes:
      slot = &layout.field_codes;
      want_element = 1;
      break;
    default:
      if ((s.flags & kSectionFlagRequired) != 0) {
        c.problems->Add("features",
                        StatusCode::kUnknownRequiredFeature,
                        entry_at + kSecOffType,
                        label + ": unknown section type " + HexPrefixed(s.type) +
                            " is marked required (flags " + HexPrefixed(s.flags) + ")");
      }
      return;
  }
  if (*slot >= 0) {
    c.problems->Add("layout",
                    StatusCode::kBadLayout,
                    entry_at + kSecOffType,
                    label + ": a second " + Quote(name) + " section (the first is section " +
                        std::to_string(*slot) + ")");
    c.bounds_ok = false;
  } else {
    *slot = static_cast<int>(i);
  }
  const bool element_ok = s.type == kSectionViews && !c.know_minor
                              ? (s.element_size >= want_element && s.element_size % 8 == 0)
                              : s.element_size == want_element;
  if (!element_ok) {
    c.problems->Add("size",
                    StatusCode::kSizeMismatch,
                    entry_at + kSecOffElementSize,
                    label + ": element_size is " + std::to_string(s.element_size) + ", expected " +
                        std::to_string(want_element));
    c.bounds_ok = false;
  }
}

// Every table entry in file order, with the zero padding between sections.
bool CheckSectionEntries(LayoutScan& c) {
  const RawHeader& h = c.layout->header;
  c.prev_end = c.table_end;
  c.prev_name = "section table";
  for (uint32_t i = 0; i < h.section_count; ++i) {
    const uint64_t entry_at = h.section_table_offset + uint64_t{i} * h.section_entry_size;
    const RawSection s = RawSection::DecodeFrom(c.b + entry_at);
    c.layout->sections.push_back(s);
    const std::string name = SectionName(s.type);
    const std::string label = "section " + std::to_string(i) + " " + Quote(name);
    CheckSectionReserved(c, s, entry_at, label);
    CheckSectionOffset(c, s, entry_at, label);
    if (!CheckSectionBounds(c, s, entry_at, label)) {
      if (c.problems->done()) return false;
      break;  // nothing after this entry can be placed
    }
    CheckSectionSize(c, s, entry_at, label);
    if (s.offset == AlignUp(c.prev_end) && c.prev_end <= s.offset) {
      CheckZeroRegion(c.b, c.prev_end, s.offset, "padding before " + label, c.problems);
    }
    CheckSectionType(c, i, s, entry_at, name, label);
    if (c.problems->done()) return false;
    c.prev_end = s.offset + s.size;
    c.prev_name = label;
  }
  return true;
}

// The footer starts at the first 64-byte boundary after the last section, zero padding between.
void CheckFooterPlacement(LayoutScan& c) {
  if (!c.bounds_ok) return;
  const uint64_t expected_footer = AlignUp(c.prev_end);
  if (expected_footer != c.footer_at) {
    c.problems->Add("layout",
                    StatusCode::kBadLayout,
                    c.footer_at,
                    "footer is at " + std::to_string(c.footer_at) + ", expected " +
                        std::to_string(expected_footer) + " (the first 64-byte boundary after " +
                        c.prev_name + ", which ends at " + std::to_string(c.prev_end) + ")");
    c.bounds_ok = false;
  } else {
    CheckZeroRegion(c.b, c.prev_end, c.footer_at, "padding before the footer", c.problems);
  }
}

// Metadata, views and points are each present; a coded shard (kFeatureCodedViews) has
// point_codes and field_codes instead of points and coarse_fields, and only a coded one has them.
bool CheckRequiredSections(LayoutScan& c) {
  const Layout& layout = *c.layout;
  const bool coded = layout.coded;
  const std::string why = coded ? " (the header's required_features has the coded-views bit)"
                                : " (the header's required_features lacks the coded-views bit)";
  struct Want {
    int slot;
    uint32_t type;
    bool present;
  };
  for (const Want& w : {Want{layout.metadata, kSectionMetadata, true},
                        Want{layout.views, kSectionViews, true},
                        Want{layout.points, kSectionPoints, !coded},
                        Want{layout.point_codes, kSectionPointCodes, coded},
                        Want{layout.field_codes, kSectionFieldCodes, coded}}) {
    if (w.present && w.slot < 0 && c.bounds_ok) {
      c.problems->Add("layout",
                      StatusCode::kBadLayout,
                      kOffSectionCount,
                      "no " + Quote(SectionName(w.type)) + " section in the section table (" +
                          std::to_string(layout.header.section_count) + " entries)" +
                          (w.type == kSectionMetadata || w.type == kSectionViews ? "" : why));
      c.bounds_ok = false;
    } else if (!w.present && w.slot >= 0) {
      c.problems->Add("layout",
                      StatusCode::kBadLayout,
                      kOffSectionCount,
                      "section " + std::to_string(w.slot) + " " + Quote(SectionName(w.type)) +
                          " is not allowed here" + why);
      c.bounds_ok = false;
    }
  }
  if (coded && layout.coarse_fields >= 0) {
    c.problems->Add("layout",
                    StatusCode::kBadLayout,
                    kOffSectionCount,
                    "section " + std::to_string(layout.coarse_fields) +
                        " 'coarse_fields' is not allowed here" + why);
    c.bounds_ok = false;
  }
  return !c.problems->done();
}

// The header's num_views / num_points equal the section counts (views and coarse_fields: one
// per view; points: one per point).
void CheckHeaderCounts(LayoutScan& c) {
  const Layout& layout = *c.layout;
  const RawHeader& h = layout.header;
  struct Count {
    int section;
    const char* name;
    const char* header_field;
    uint64_t header_value;
    size_t header_offset;
  };
  for (const Count& k :
       {Count{layout.views, "views", "num_views", h.num_views, kOffNumViews},
        Count{layout.coarse_fields, "coarse_fields", "num_views", h.num_views, kOffNumViews},
        Count{layout.points, "points", "num_points", h.num_points, kOffNumPoints}}) {
    if (k.section < 0) continue;
    const uint64_t count = layout.sections[static_cast<size_t>(k.section)].count;
    if (count == k.header_value) continue;
    c.problems->Add("counts",
                    StatusCode::kSizeMismatch,
                    k.header_offset,
                    std::string("header ") + k.header_field + " is " +
                        std::to_string(k.header_value) + " but the " + k.name + " section holds " +
                        std::to_string(count));
  }
}

// View i's reserved flags (record at file offset `at`) are zero.
void CheckViewFlags(LayoutScan& c, uint64_t i, uint64_t at) {
  const uint32_t flags = LoadLittleEndian<uint32_t>(c.b + at + kViewOffFlags);
  if (flags != 0 && c.know_minor) {
    c.problems->Add("reserved",
                    StatusCode::kNonZeroReserved,
                    at + kViewOffFlags,
                    "view " + std::to_string(i) + ": reserved flags are " + HexPrefixed(flags) +
                        ", expected 0");
  }
}

// Every view's point range, before anyone takes a span of it: inside the points section, in
// order, covering it exactly. Sets layout->views_ok (unless stopped early).
void CheckViewRanges(LayoutScan& c) {
  Layout& layout = *c.layout;
  const RawSection& vs = layout.sections[layout.views];
  const RawSection& ps = layout.sections[layout.points];
  bool views_ok = true;
  uint64_t running = 0;
  for (uint64_t i = 0; i < vs.count; ++i) {
    const uint64_t at = vs.offset + i * vs.element_size;
    const uint8_t* rec = c.b + at;
    CheckViewFlags(c, i, at);
    const uint64_t off = LoadLittleEndian<uint64_t>(rec + kViewOffPointOffset);
    const uint32_t cnt = LoadLittleEndian<uint32_t>(rec + kViewOffPointCount);
    if (off > ps.count || cnt > ps.count - off) {
      c.problems->Add("view-range",
                      StatusCode::kOutOfRange,
                      at + kViewOffPointOffset,
                      "view " + std::to_string(i) + ": points [" + std::to_string(off) + ", +" +
                          std::to_string(cnt) + ") lie outside the points section (" +
                          std::to_string(ps.count) + " points)");
      views_ok = false;
    } else if (off != running) {
      c.problems->Add("view-range",
                      StatusCode::kBadLayout,
                      at + kViewOffPointOffset,
                      "view " + std::to_string(i) + ": point_offset is " + std::to_string(off) +
                          ", expected " + std::to_string(running) +
                          " (views must cover the points in order without holes or overlaps)");
      views_ok = false;
    }
    if (c.problems->done()) return;
    running = (off <= ps.count && cnt <= ps.count - off) ? off + cnt : running + cnt;
  }
  if (running != ps.count) {
    c.problems->Add("view-range",
                    StatusCode::kBadLayout,
                    vs.offset,
                    "views cover " + std::to_string(running) +
                        " points, the points section holds " + std::to_string(ps.count));
    views_ok = false;
  }
  layout.views_ok = views_ok;
}

// A coded shard's view records: each view's point_offset is the byte offset of its code in
// point_codes, starting at 0 and strictly increasing (a code is at least its mode byte), the
// last code ending at the section's end; the counts add up to the header's num_points; and the
// field_codes offset table is in bounds and in order. Sets layout->views_ok.
void CheckCodeRanges(LayoutScan& c) {
  Layout& layout = *c.layout;
  const RawSection& vs = layout.sections[layout.views];
  const RawSection& pc = layout.sections[static_cast<size_t>(layout.point_codes)];
  const RawSection& fc = layout.sections[static_cast<size_t>(layout.field_codes)];
  bool views_ok = true;
  uint64_t points = 0;
  uint64_t prev = 0;
  for (uint64_t i = 0; i < vs.count; ++i) {
    const uint64_t at = vs.offset + i * vs.element_size;
    const uint8_t* rec = c.b + at;
    CheckViewFlags(c, i, at);
    const uint64_t off = LoadLittleEndian<uint64_t>(rec + kViewOffPointOffset);
    points += LoadLittleEndian<uint32_t>(rec + kViewOffPointCount);
    const bool first = i == 0;
    if ((first && off != 0) || (!first && off <= prev) || off >= pc.size) {
      c.problems->Add(
          "view-range",
          StatusCode::kBadLayout,
          at + kViewOffPointOffset,
          "view " + std::to_string(i) + ": point code offset is " + std::to_string(off) +
              ", expected " + (first ? std::string("0") : "more than " + std::to_string(prev)) +
              " and less than the point_codes section's " + std::to_string(pc.size) + " bytes");
      views_ok = false;
    }
    if (c.problems->done()) return;
    prev = off;
  }
  if (vs.count == 0 && pc.size != 0) {
    c.problems->Add(
        "view-range",
        StatusCode::kBadLayout,
        pc.offset,
        "no views, but the point_codes section holds " + std::to_string(pc.size) + " bytes");
    views_ok = false;
  }
  if (points != layout.header.num_points) {
    c.problems->Add("counts",
                    StatusCode::kSizeMismatch,
                    kOffNumPoints,
                    "header num_points is " + std::to_string(layout.header.num_points) +
                        " but the views' point counts add up to " + std::to_string(points));
  }
  // field_codes: the offset table.
  const uint64_t table_bytes = 8 * (vs.count + 1);
  if (fc.size < table_bytes) {
    c.problems->Add("view-range",
                    StatusCode::kTruncated,
                    fc.offset,
                    "field_codes section is " + std::to_string(fc.size) +
                        " bytes, too small for its offset table of " +
                        std::to_string(vs.count + 1) + " entries");
    layout.views_ok = false;
    return;
  }
  uint64_t last = table_bytes;
  for (uint64_t i = 0; i <= vs.count; ++i) {
    const uint64_t at = fc.offset + 8 * i;
    const uint64_t off = LoadLittleEndian<uint64_t>(c.b + at);
    const bool ok = i == 0 ? off == table_bytes
                           : (off >= last && off <= fc.size && (i < vs.count || off == fc.size));
    if (!ok) {
      c.problems->Add("view-range",
                      StatusCode::kBadLayout,
                      at,
                      "field_codes offset " + std::to_string(i) + " is " + std::to_string(off) +
                          ", expected " +
                          (i == 0 ? std::to_string(table_bytes)
                                  : (i == vs.count ? std::to_string(fc.size)
                                                   : "between " + std::to_string(last) + " and " +
                                                         std::to_string(fc.size))));
      views_ok = false;
      if (c.problems->done()) return;
      break;
    }
    last = off;
  }
  layout.views_ok = views_ok;
}

}  // namespace

Layout CheckLayout(std::span<const uint8_t> bytes, ProblemList* problems) {
  Layout layout;
  LayoutScan c;
  c.b = bytes.data();
  c.n = bytes.size();
  c.problems = problems;
  c.layout = &layout;
  // Header: fatal problems first (nothing after them can be interpreted).
  if (!CheckMagic(c) || !CheckMinimumSize(c)) return layout;
  layout.header = RawHeader::DecodeFrom(bytes);
  c.know_minor = layout.header.version_minor <= kVersionMinor;
  layout.coded = (layout.header.required_features & kFeatureCodedViews) != 0;
  c.footer_at = c.n - kFooterSize;
  if (!CheckVersion(c) || !CheckHeaderSize(c) || !CheckHeaderChecksum(c) || !CheckFileSize(c) ||
      !CheckRequiredFeatures(c) || !CheckHeaderReserved(c)) {
    return layout;
  }
  if (!CheckFooterMagic(c) || !CheckFooterSize(c)) return layout;
  if (!CheckTableOffset(c) || !CheckTableEntrySize(c) || !CheckTableCount(c) || !CheckTableEnd(c) ||
      !CheckTableChecksum(c)) {
    return layout;
  }
  if (!CheckSectionEntries(c)) return layout;
  CheckFooterPlacement(c);
  if (!CheckRequiredSections(c)) return layout;
  CheckHeaderCounts(c);
  const bool data_ok =
      layout.coded ? layout.point_codes >= 0 && layout.field_codes >= 0 : layout.points >= 0;
  if (!c.bounds_ok || layout.metadata < 0 || layout.views < 0 || !data_ok) return layout;
  layout.structure_ok = true;
  if (problems->done()) return layout;
  layout.view_stride = layout.sections[layout.views].element_size;
  if (layout.coded) {
    CheckCodeRanges(c);
  } else {
    CheckViewRanges(c);
  }
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

namespace {

// Name of the label float at `offset` inside a view record.
std::string FieldName(size_t offset) {
  auto idx = [&](size_t base) { return std::to_string((offset - base) / 4); };
  if (offset < kViewOffViewDirection) return "joint_angles[" + idx(kViewOffJointAngles) + "]";
  if (offset < kViewOffViewTheta) return "view_direction[" + idx(kViewOffViewDirection) + "]";
  if (offset == kViewOffViewTheta) return "view_theta";
  if (offset == kViewOffViewPhi) return "view_phi";
  if (offset == kViewOffCameraRoll) return "camera_roll";
  if (offset < kViewOffSourceDiameter) {
    const size_t k = (offset - kViewOffKeypoints) / 4;
    return "keypoints[" + std::to_string(k / 3) + "][" + std::to_string(k % 3) + "]";
  }
  if (offset == kViewOffSourceDiameter) return "source_diameter_px";
  if (offset == kViewOffScale) return "scale";
  return "source_centre_px[" + idx(kViewOffSourceCentre) + "]";
}

}  // namespace

bool CheckLabelRanges(const uint8_t* rec,
                      uint64_t at,
                      uint64_t index,
                      const JointLimits* limits,
                      double tolerance,
                      const std::string& limits_source,
                      ProblemList* problems) {
  // Built only for a message: the reader runs this over every view at open.
  auto view = [index] { return "view " + std::to_string(index) + ": "; };
  // Fast path for the common good record: an f32 is NaN or infinite iff its exponent bits are all
  // set; OR-ing that over the record vectorises, and the message loop runs only on a bad one.
  uint32_t any_non_finite = 0;
  for (size_t o = kViewFloatsBegin; o < kViewFloatsEnd; o += 4) {
    any_non_finite |=
        static_cast<uint32_t>((LoadLittleEndian<uint32_t>(rec + o) & 0x7f800000u) == 0x7f800000u);
  }
  bool finite = true;
  for (size_t o = kViewFloatsBegin; any_non_finite != 0 && o < kViewFloatsEnd; o += 4) {
    const float v = LoadLittleEndian<float>(rec + o);
    if (!std::isfinite(v)) {
      problems->Add("label-finite",
                    StatusCode::kOutOfRange,
                    at + o,
                    view() + FieldName(o) + " is " + FormatValue(v) + " (not finite)");
      if (problems->done()) return false;
      finite = false;
    }
  }
  for (auto [offset, field] : {std::pair{kViewOffRenderId, "render_id"},
                               std::pair{kViewOffShapeId, "shape_id"},
                               std::pair{kViewOffDirId, "dir_id"}}) {
    if (LoadLittleEndian<uint32_t>(rec + offset) == kInvalidRenderId) {
      problems->Add("label-id",
                    StatusCode::kOutOfRange,
                    at,
                    view() + field + " is 0xffffffff (the invalid id: never filled in)");
      if (problems->done()) return finite;
    }
  }
  if (!finite) return false;
  for (int j = 0; j < kNumJointAngles; ++j) {
    const double a = LoadLittleEndian<float>(rec + kViewOffJointAngles + 4 * j);
    const double lo = limits ? limits->min[j] : -kMaxAbsAngle;
    const double hi = limits ? limits->max[j] : kMaxAbsAngle;
    if (a < lo - tolerance || a > hi + tolerance) {
      problems->Add("label-joints",
                    StatusCode::kOutOfRange,
                    at + kViewOffJointAngles + 4 * j,
                    view() + "joint_angles[" + std::to_string(j) + "] = " + FormatValue(a) +
                        " rad is outside [" + FormatValue(lo) + ", " + FormatValue(hi) + "] (" +
                        (limits ? limits_source : "no hand model: +-2 pi") + ")");
      if (problems->done()) return true;
    }
  }
  const float roll = LoadLittleEndian<float>(rec + kViewOffCameraRoll);
  constexpr double kAngleTolerance = 1e-3;  // rad: a roll of exactly 2 pi in float rounds up
  if (std::abs(roll) > kMaxAbsAngle + kAngleTolerance) {
    problems->Add("label-roll",
                  StatusCode::kOutOfRange,
                  at + kViewOffCameraRoll,
                  view() + "camera_roll is " + FormatValue(roll) + " rad, outside [-2 pi, 2 pi]");
    if (problems->done()) return true;
  }
  for (int k = 0; k < kNumKeypoints; ++k) {
    const uint8_t* kp = rec + kViewOffKeypoints + 12 * k;
    const float x = LoadLittleEndian<float>(kp), y = LoadLittleEndian<float>(kp + 4),
                z = LoadLittleEndian<float>(kp + 8);
    if (std::abs(x) > kMaxAbsKeypointXY || std::abs(y) > kMaxAbsKeypointXY ||
        std::abs(z) > kMaxAbsKeypointZ) {
      problems->Add("label-keypoints",
                    StatusCode::kOutOfRange,
                    at + kViewOffKeypoints + 12 * k,
                    view() + "keypoint " + std::to_string(k) + " (" + FormatValue(x) + ", " +
                        FormatValue(y) + ", " + FormatValue(z) +
                        ") px is outside |x|,|y| <= " + FormatValue(kMaxAbsKeypointXY) +
                        ", |z| <= " + FormatValue(kMaxAbsKeypointZ));
      if (problems->done()) return true;
    }
  }
  return true;
}

void CheckViewLabels(std::span<const uint8_t> bytes, const Layout& layout, ProblemList* problems) {
  THROW_CHECK(layout.structure_ok);
  const RawSection& vs = layout.sections[layout.views];
  for (uint64_t i = 0; i < vs.count && !problems->done(); ++i) {
    const uint64_t at = vs.offset + i * layout.view_stride;
    CheckLabelRanges(bytes.data() + at, at, i, nullptr, 0.0, "", problems);
  }
}

}  // namespace handdb::shard
