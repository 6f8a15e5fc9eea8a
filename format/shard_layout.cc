#include "format/shard_layout.h"

#include <fcntl.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <sstream>
#include <utility>

#include "base/atomic_file.h"
#include "base/hex.h"

namespace handdb::shard {

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
  if (Status s = CheckRegularFile(path); !s.ok()) return s;  // a FIFO would block open() and read()
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
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
    case kSectionCoarseFields:
      return "coarse_fields";
    case kSectionPointCodes:
      return "point_codes";
    case kSectionFieldCodes:
      return "field_codes";
    default:
      return "unknown(" + HexPrefixed(type) + ")";
  }
}

std::string FormatValue(double v) {
  std::ostringstream os;
  os.precision(9);
  os << v;
  return os.str();
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
