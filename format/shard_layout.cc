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

RawHeader RawHeader::DecodeFrom(std::span<const uint8_t> bytes) {
  THROW_CHECK_GE(bytes.size(), kHeaderSize);
  const uint8_t* b = bytes.data();
  RawHeader h;
  std::memcpy(h.magic.data(), b + kOffMagic, 8);
  h.version_major = LoadLittleEndian<uint16_t>(b + kOffVersionMajor);
  h.version_minor = LoadLittleEndian<uint16_t>(b + kOffVersionMinor);
  h.header_size = LoadLittleEndian<uint32_t>(b + kOffHeaderSize);
  h.required_features = LoadLittleEndian<uint64_t>(b + kOffRequiredFeatures);
  h.optional_features = LoadLittleEndian<uint64_t>(b + kOffOptionalFeatures);
  h.file_size = LoadLittleEndian<uint64_t>(b + kOffFileSize);
  h.num_views = LoadLittleEndian<uint64_t>(b + kOffNumViews);
  h.num_points = LoadLittleEndian<uint64_t>(b + kOffNumPoints);
  h.section_table_offset = LoadLittleEndian<uint64_t>(b + kOffSectionTableOffset);
  h.section_count = LoadLittleEndian<uint32_t>(b + kOffSectionCount);
  h.section_entry_size = LoadLittleEndian<uint32_t>(b + kOffSectionEntrySize);
  h.section_table_checksum = LoadLittleEndian<uint64_t>(b + kOffSectionTableChecksum);
  if (h.header_size >= kOffHeaderReserved + 8 && h.header_size <= bytes.size()) {
    h.header_checksum = LoadLittleEndian<uint64_t>(b + h.header_size - 8);
  }
  return h;
}

uint64_t HeaderChecksum(std::span<const uint8_t> header_bytes) {
  THROW_CHECK_GE(header_bytes.size(), 8u);
  return Checksum(header_bytes.data(), header_bytes.size() - 8);
}

void RawHeader::EncodeTo(std::span<uint8_t> out) const {
  const RawHeader& h = *this;
  THROW_CHECK_EQ(h.header_size, kHeaderSize);
  THROW_CHECK_GE(out.size(), kHeaderSize);
  uint8_t* b = out.data();
  std::memset(b, 0, kHeaderSize);
  std::memcpy(b + kOffMagic, h.magic.data(), 8);
  StoreLittleEndian<uint16_t>(b + kOffVersionMajor, h.version_major);
  StoreLittleEndian<uint16_t>(b + kOffVersionMinor, h.version_minor);
  StoreLittleEndian<uint32_t>(b + kOffHeaderSize, h.header_size);
  StoreLittleEndian<uint64_t>(b + kOffRequiredFeatures, h.required_features);
  StoreLittleEndian<uint64_t>(b + kOffOptionalFeatures, h.optional_features);
  StoreLittleEndian<uint64_t>(b + kOffFileSize, h.file_size);
  StoreLittleEndian<uint64_t>(b + kOffNumViews, h.num_views);
  StoreLittleEndian<uint64_t>(b + kOffNumPoints, h.num_points);
  StoreLittleEndian<uint64_t>(b + kOffSectionTableOffset, h.section_table_offset);
  StoreLittleEndian<uint32_t>(b + kOffSectionCount, h.section_count);
  StoreLittleEndian<uint32_t>(b + kOffSectionEntrySize, h.section_entry_size);
  StoreLittleEndian<uint64_t>(b + kOffSectionTableChecksum, h.section_table_checksum);
  StoreLittleEndian<uint64_t>(b + kHeaderSize - 8,
                              HeaderChecksum(std::span<const uint8_t>(b, kHeaderSize)));
}

RawSection RawSection::DecodeFrom(const uint8_t* e) {
  RawSection s;
  s.type = LoadLittleEndian<uint32_t>(e + kSecOffType);
  s.flags = LoadLittleEndian<uint32_t>(e + kSecOffFlags);
  s.offset = LoadLittleEndian<uint64_t>(e + kSecOffOffset);
  s.size = LoadLittleEndian<uint64_t>(e + kSecOffSize);
  s.count = LoadLittleEndian<uint64_t>(e + kSecOffCount);
  s.element_size = LoadLittleEndian<uint32_t>(e + kSecOffElementSize);
  s.reserved = LoadLittleEndian<uint32_t>(e + kSecOffReserved);
  s.checksum = LoadLittleEndian<uint64_t>(e + kSecOffChecksum);
  return s;
}

void RawSection::EncodeTo(uint8_t* e) const {
  const RawSection& s = *this;
  std::memset(e, 0, kSectionEntrySize);
  StoreLittleEndian<uint32_t>(e + kSecOffType, s.type);
  StoreLittleEndian<uint32_t>(e + kSecOffFlags, s.flags);
  StoreLittleEndian<uint64_t>(e + kSecOffOffset, s.offset);
  StoreLittleEndian<uint64_t>(e + kSecOffSize, s.size);
  StoreLittleEndian<uint64_t>(e + kSecOffCount, s.count);
  StoreLittleEndian<uint32_t>(e + kSecOffElementSize, s.element_size);
  StoreLittleEndian<uint32_t>(e + kSecOffReserved, s.reserved);
  StoreLittleEndian<uint64_t>(e + kSecOffChecksum, s.checksum);
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
  l.render_id = LoadLittleEndian<uint32_t>(r + kViewOffRenderId);
  l.shape_id = LoadLittleEndian<uint32_t>(r + kViewOffShapeId);
  l.dir_id = LoadLittleEndian<uint32_t>(r + kViewOffDirId);
  l.flags = LoadLittleEndian<uint32_t>(r + kViewOffFlags);
  std::memcpy(l.joint_angles.data(), r + kViewOffJointAngles, sizeof(float) * kNumJointAngles);
  std::memcpy(l.view_direction.data(), r + kViewOffViewDirection, sizeof(float) * 3);
  l.view_theta = LoadLittleEndian<float>(r + kViewOffViewTheta);
  l.view_phi = LoadLittleEndian<float>(r + kViewOffViewPhi);
  l.camera_roll = LoadLittleEndian<float>(r + kViewOffCameraRoll);
  for (int k = 0; k < kNumKeypoints; ++k) {
    std::memcpy(l.keypoints[k].data(), r + kViewOffKeypoints + 12 * k, 12);
  }
  l.source_diameter_px = LoadLittleEndian<float>(r + kViewOffSourceDiameter);
  l.scale = LoadLittleEndian<float>(r + kViewOffScale);
  std::memcpy(l.source_centre_px.data(), r + kViewOffSourceCentre, 8);
  return l;
}

void EncodeViewRecord(const ViewLabel& l, uint64_t point_offset, uint32_t point_count, uint8_t* r) {
  std::memset(r, 0, kViewRecordSize);
  StoreLittleEndian<uint32_t>(r + kViewOffRenderId, l.render_id);
  StoreLittleEndian<uint32_t>(r + kViewOffShapeId, l.shape_id);
  StoreLittleEndian<uint32_t>(r + kViewOffDirId, l.dir_id);
  StoreLittleEndian<uint32_t>(r + kViewOffFlags, l.flags);
  std::memcpy(r + kViewOffJointAngles, l.joint_angles.data(), sizeof(float) * kNumJointAngles);
  std::memcpy(r + kViewOffViewDirection, l.view_direction.data(), sizeof(float) * 3);
  StoreLittleEndian<float>(r + kViewOffViewTheta, l.view_theta);
  StoreLittleEndian<float>(r + kViewOffViewPhi, l.view_phi);
  StoreLittleEndian<float>(r + kViewOffCameraRoll, l.camera_roll);
  for (int k = 0; k < kNumKeypoints; ++k) {
    std::memcpy(r + kViewOffKeypoints + 12 * k, l.keypoints[k].data(), 12);
  }
  StoreLittleEndian<float>(r + kViewOffSourceDiameter, l.source_diameter_px);
  StoreLittleEndian<float>(r + kViewOffScale, l.scale);
  std::memcpy(r + kViewOffSourceCentre, l.source_centre_px.data(), 8);
  StoreLittleEndian<uint32_t>(r + kViewOffPointCount, point_count);
  StoreLittleEndian<uint64_t>(r + kViewOffPointOffset, point_offset);
}

bool RewriteChecksums(std::span<uint8_t> bytes) {
  const uint64_t n = bytes.size();
  if (n < kMinFileSize) return false;
  uint8_t* b = bytes.data();
  const RawHeader h = RawHeader::DecodeFrom(bytes);
  if (h.header_size < kHeaderSize || h.header_size > n ||
      h.section_entry_size < kSectionEntrySize || h.section_count > kMaxSections ||
      h.section_table_offset > n) {
    return false;
  }
  const uint64_t table_bytes = uint64_t{h.section_count} * h.section_entry_size;
  if (table_bytes > n - h.section_table_offset) return false;
  for (uint32_t i = 0; i < h.section_count; ++i) {
    uint8_t* e = b + h.section_table_offset + uint64_t{i} * h.section_entry_size;
    const RawSection s = RawSection::DecodeFrom(e);
    if (s.offset > n || s.size > n - s.offset) return false;
    StoreLittleEndian<uint64_t>(e + kSecOffChecksum, Checksum(b + s.offset, s.size));
  }
  StoreLittleEndian<uint64_t>(b + kOffSectionTableChecksum,
                              Checksum(b + h.section_table_offset, table_bytes));
  StoreLittleEndian<uint64_t>(
      b + h.header_size - 8,
      HeaderChecksum(std::span<const uint8_t>(b, static_cast<size_t>(h.header_size))));
  return true;
}

}  // namespace handdb::shard
