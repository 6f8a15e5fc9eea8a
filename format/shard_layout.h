// The byte layout of a shard (docs/format.md) and the codecs of its structs. Decoding
// (RawHeader::DecodeFrom, RawSection::DecodeFrom) only reads bytes; meaning (CheckLayout,
// CheckSectionChecksums: format/shard_checks.h) is checked separately, and every problem goes to
// a ProblemList, which either stops at the first problem (the reader) or collects all of them
// (the validator). Little-endian on disk (base/endian.h); the label arrays are copied whole, so
// this code assumes a little-endian host.
#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <cstring>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "base/endian.h"
#include "base/status.h"
#include "format/view.h"

namespace handdb::shard {

static_assert(std::endian::native == std::endian::little,
              "handdb shards are little-endian; a big-endian host needs byte swapping here");

// First byte non-ASCII (catches 7-bit transfers), CR LF / LF catch newline translation, 0x1a stops
// `type` on DOS (after PNG).
constexpr std::array<uint8_t, 8> kMagic = {0x89, 'H', 'D', 'B', '\r', '\n', 0x1a, '\n'};
constexpr uint16_t kVersionMajor = 1;
// 1.1: the optional coarse-fields section. 1.2: coded views (kFeatureCodedViews), written only
// by a writer asked for them; every other shard is still written as 1.1.
constexpr uint16_t kVersionMinor = 2;
constexpr uint16_t kVersionMinorPlain = 1;

constexpr uint64_t kAlignment = 64;
constexpr uint32_t kHeaderSize = 128;       // v1.0 header; newer minors may grow it
constexpr uint32_t kSectionEntrySize = 48;  // v1.0 entry; newer minors may grow it
constexpr uint64_t kFooterSize = 16;        // u64 file_size + magic
constexpr uint32_t kMaxSections = 4096;     // sanity bound on section_count
constexpr uint64_t kMinFileSize = kHeaderSize + kFooterSize;

// Header field offsets (bytes from the start of the file).
constexpr size_t kOffMagic = 0;
constexpr size_t kOffVersionMajor = 8;
constexpr size_t kOffVersionMinor = 10;
constexpr size_t kOffHeaderSize = 12;
constexpr size_t kOffRequiredFeatures = 16;
constexpr size_t kOffOptionalFeatures = 24;
constexpr size_t kOffFileSize = 32;
constexpr size_t kOffNumViews = 40;
constexpr size_t kOffNumPoints = 48;
constexpr size_t kOffSectionTableOffset = 56;
constexpr size_t kOffSectionCount = 64;
constexpr size_t kOffSectionEntrySize = 68;
constexpr size_t kOffSectionTableChecksum = 72;
constexpr size_t kOffHeaderReserved = 80;  // up to header_size - 8, zero
// The header checksum is the last 8 bytes of the header (offset header_size - 8).

// Required feature bits. v1.2 defines one: the shard's points and coarse fields are coded
// (format/point_codec.h, format/field_codec.h) in the point_codes and field_codes sections
// instead of the points and coarse_fields sections (docs/format.md section 10). A reader that
// does not know a required bit refuses the file (a v1.1 reader finds no points to read).
constexpr uint64_t kFeatureCodedViews = 1u << 0;
constexpr uint64_t kKnownRequiredFeatures = kFeatureCodedViews;

// Section types.
constexpr uint32_t kSectionMetadata = 1;  // UTF-8 JSON object, element_size 1
constexpr uint32_t kSectionViews = 2;     // fixed-stride view records, element_size kViewRecordSize
constexpr uint32_t kSectionPoints = 3;    // PointQ array, element_size 4
// v1.1, optional: one coarse distance field per view (format/coarse_field.h), in view order;
// element_size kCoarseFieldSize, count = num_views. Readers that do not know it skip it.
constexpr uint32_t kSectionCoarseFields = 4;
constexpr uint32_t kCoarseFieldSize = 1849;  // CoarseGrid::kCells
// v1.2, required in a shard with kFeatureCodedViews (and only there), element_size 1:
// point_codes: each view's EncodeViewPoints code, in view order, back to back; the record's
// point_offset is the byte offset of its code, which ends where the next view's begins (the last
// at the section's end); point_count is the number of points the code decodes to.
constexpr uint32_t kSectionPointCodes = 5;
// field_codes: num_views + 1 u64 byte offsets (relative to the section; the first is
// 8 (num_views + 1), the last the section's size, non-decreasing), then each view's
// EncodeCoarseField code in view order: view i's is [offset[i], offset[i + 1]).
constexpr uint32_t kSectionFieldCodes = 6;
// Section flags.
constexpr uint32_t kSectionFlagRequired = 1u
                                          << 0;  // a reader that does not know the type must refuse
constexpr uint32_t kKnownSectionFlags = kSectionFlagRequired;

// Section-table entry field offsets (relative to the entry).
constexpr size_t kSecOffType = 0;
constexpr size_t kSecOffFlags = 4;
constexpr size_t kSecOffOffset = 8;
constexpr size_t kSecOffSize = 16;
constexpr size_t kSecOffCount = 24;
constexpr size_t kSecOffElementSize = 32;
constexpr size_t kSecOffReserved = 36;
constexpr size_t kSecOffChecksum = 40;

// View record (one per canonical view), little-endian, fields at these offsets.
constexpr uint32_t kViewRecordSize = 400;
constexpr size_t kViewOffRenderId = 0;
constexpr size_t kViewOffShapeId = 4;
constexpr size_t kViewOffDirId = 8;
constexpr size_t kViewOffFlags = 12;          // reserved, zero
constexpr size_t kViewOffJointAngles = 16;    // f32[20]
constexpr size_t kViewOffViewDirection = 96;  // f32[3]
constexpr size_t kViewOffViewTheta = 108;
constexpr size_t kViewOffViewPhi = 112;
constexpr size_t kViewOffCameraRoll = 116;
constexpr size_t kViewOffKeypoints = 120;  // f32[21][3]
constexpr size_t kViewOffSourceDiameter = 372;
constexpr size_t kViewOffScale = 376;
constexpr size_t kViewOffSourceCentre = 380;  // f32[2]
constexpr size_t kViewOffPointCount = 388;    // u32
constexpr size_t kViewOffPointOffset = 392;   // u64, index into the points section
constexpr size_t kViewFloatsBegin = kViewOffJointAngles;
constexpr size_t kViewFloatsEnd = kViewOffPointCount;  // every f32 of the label lies in between

constexpr uint32_t kPointSize = sizeof(PointQ);
// Largest |x| or |y| of a stored point: 384 px (twice the normalised diameter) in 1/16 px.
constexpr int kMaxAbsPointCoord = 6144;

inline constexpr uint64_t AlignUp(uint64_t x) { return (x + kAlignment - 1) & ~(kAlignment - 1); }

// XXH3-64 with seed 0, the only checksum the format uses.
uint64_t Checksum(const void* data, size_t size);
// 16 lowercase hex digits (the canonical big-endian form xxhsum -H3 prints).
std::string ChecksumHex(uint64_t checksum);

// XXH3-64 (seed 0) over data fed in pieces; equals Checksum() of the concatenation.
class StreamingChecksum {
 public:
  StreamingChecksum();
  ~StreamingChecksum();
  StreamingChecksum(const StreamingChecksum&) = delete;
  StreamingChecksum& operator=(const StreamingChecksum&) = delete;
  void Reset();
  void Update(const void* data, size_t size);
  uint64_t Digest() const;

 private:
  void* state_;  // XXH3_state_t, kept out of this header
};

// XXH3-64 of a whole file, read sequentially with pread (kNotFound / kIoError name the path).
Result<uint64_t> FileChecksum(const std::string& path);

struct RawHeader {
  std::array<uint8_t, 8> magic{};
  uint16_t version_major = 0;
  uint16_t version_minor = 0;
  uint32_t header_size = 0;
  uint64_t required_features = 0;
  uint64_t optional_features = 0;
  uint64_t file_size = 0;
  uint64_t num_views = 0;
  uint64_t num_points = 0;
  uint64_t section_table_offset = 0;
  uint32_t section_count = 0;
  uint32_t section_entry_size = 0;
  uint64_t section_table_checksum = 0;
  uint64_t header_checksum = 0;  // at header_size - 8 (when that lies inside the bytes given)

  // Decodes the fixed v1 fields from `bytes` (needs at least kHeaderSize bytes; THROW_CHECK).
  static RawHeader DecodeFrom(std::span<const uint8_t> bytes);
  // Writes a v1.0 header into out[0, kHeaderSize): reserved bytes zero, header_checksum computed.
  void EncodeTo(std::span<uint8_t> out) const;
};

struct RawSection {
  uint32_t type = 0;
  uint32_t flags = 0;
  uint64_t offset = 0;
  uint64_t size = 0;
  uint64_t count = 0;
  uint32_t element_size = 0;
  uint32_t reserved = 0;
  uint64_t checksum = 0;

  // A section table entry of kSectionEntrySize bytes.
  static RawSection DecodeFrom(const uint8_t* entry);
  void EncodeTo(uint8_t* entry) const;
};

// Checksum of the header bytes [0, header_size - 8).
uint64_t HeaderChecksum(std::span<const uint8_t> header_bytes);

// A float for messages: up to 9 significant digits ("2.5", "nan", "inf").
std::string FormatValue(double v);

// "metadata", "views", "points" or "unknown(0x...)".
std::string SectionName(uint32_t type);

// Decodes the label fields of a view record (no range checks).
ViewLabel DecodeViewLabel(const uint8_t* record);
// Encodes a label + point range into a record of kViewRecordSize bytes (reserved fields zero).
void EncodeViewRecord(const ViewLabel& label,
                      uint64_t point_offset,
                      uint32_t point_count,
                      uint8_t* record);

// For tests and tools that patch a shard on purpose: recomputes every section checksum, the
// table checksum and the header checksum in place, using the table as it stands. Returns false if
// the structure is too broken to locate them.
bool RewriteChecksums(std::span<uint8_t> bytes);

}  // namespace handdb::shard
