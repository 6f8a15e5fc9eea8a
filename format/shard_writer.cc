#include "format/shard_writer.h"

#include <array>
#include <cmath>
#include <vector>

#include "base/atomic_file.h"
#include "format/coarse_field.h"
#include "format/field_codec.h"
#include "format/point_codec.h"
#include "format/shard_checks.h"
#include "format/shard_layout.h"

namespace handdb {
namespace {

using namespace shard;  // NOLINT(google-build-using-namespace): the layout constants

constexpr size_t kWriteBufferSize = 1 << 20;

bool AllFinite(const ViewLabel& l) {
  auto finite = [](float v) { return std::isfinite(v); };
  for (float v : l.joint_angles) {
    if (!finite(v)) return false;
  }
  for (float v : l.view_direction) {
    if (!finite(v)) return false;
  }
  for (const auto& kp : l.keypoints) {
    for (float v : kp) {
      if (!finite(v)) return false;
    }
  }
  return finite(l.view_theta) && finite(l.view_phi) && finite(l.camera_roll) &&
         finite(l.source_diameter_px) && finite(l.scale) && finite(l.source_centre_px[0]) &&
         finite(l.source_centre_px[1]);
}

}  // namespace

bool ShardWriterOptions::Check() const {
  CHECK_OPTION(!metadata_json.empty());
  for (const auto& s : extra_sections) {
    CHECK_OPTION(s.type != kSectionMetadata && s.type != kSectionViews &&
                 s.type != kSectionPoints && s.type != kSectionCoarseFields &&
                 s.type != kSectionPointCodes && s.type != kSectionFieldCodes);
    CHECK_OPTION(s.type != 0);
    CHECK_OPTION((s.flags & ~kKnownSectionFlags) == 0);
  }
  return true;
}

struct ShardWriter::Impl {
  AtomicFileWriter file;
  ShardWriterOptions options;
  std::vector<uint8_t> buffer;      // pending bytes not yet handed to the file
  std::vector<uint8_t> view_table;  // kViewRecordSize per view, written at Finish()
  std::vector<uint8_t> coarse;      // kCoarseFieldSize per view, written at Finish()
  // Coded shards: the field codes and their end offsets (relative to the first code), written at
  // Finish(); the point codes stream out where a plain shard's points go.
  std::string field_codes;
  std::vector<uint64_t> field_code_ends;
  std::string code;  // one view's point code (reused)
  uint64_t code_bytes = 0;
  StreamingChecksum points_hash;
  uint64_t num_points = 0;
  uint64_t points_offset = 0;
  uint64_t metadata_offset = 0;
  uint64_t num_sections = 0;
  bool open = false;

  Status Flush() {
    if (buffer.empty()) return Status::Ok();
    Status s = file.Write(buffer.data(), buffer.size());
    buffer.clear();
    return s;
  }
  Status Append(const void* data, size_t size) {
    const auto* p = static_cast<const uint8_t*>(data);
    if (buffer.size() + size > kWriteBufferSize) {
      HANDDB_RETURN_IF_ERROR(Flush());
      if (size >= kWriteBufferSize) return file.Write(p, size);
    }
    buffer.insert(buffer.end(), p, p + size);
    return Status::Ok();
  }
  uint64_t Position() const { return file.bytes_written() + buffer.size(); }
  Status PadTo64() {
    static constexpr uint8_t kZeros[kAlignment] = {};
    const uint64_t pos = Position();
    return Append(kZeros, AlignUp(pos) - pos);
  }
};

ShardWriter::ShardWriter() : impl_(std::make_unique<Impl>()) {}
ShardWriter::~ShardWriter() = default;  // AtomicFileWriter removes an uncommitted temp file

Status ShardWriter::Open(const std::filesystem::path& path, const ShardWriterOptions& options) {
  THROW_CHECK_MSG(!impl_->open, "ShardWriter::Open called twice");
  THROW_CHECK(options.Check());
  Impl& w = *impl_;
  w.options = options;
  w.buffer.reserve(kWriteBufferSize);
  HANDDB_RETURN_IF_ERROR(w.file.Open(path));
  w.open = true;
  // Header and section table are placeholders, patched by Finish() once sizes are known.
  w.num_sections =
      3 + (options.coarse_fields || options.coded ? 1 : 0) + options.extra_sections.size();
  std::vector<uint8_t> head(kHeaderSize + w.num_sections * kSectionEntrySize, 0);
  HANDDB_RETURN_IF_ERROR(w.Append(head.data(), head.size()));
  HANDDB_RETURN_IF_ERROR(w.PadTo64());
  w.metadata_offset = w.Position();
  HANDDB_RETURN_IF_ERROR(w.Append(options.metadata_json.data(), options.metadata_json.size()));
  HANDDB_RETURN_IF_ERROR(w.PadTo64());
  w.points_offset = w.Position();
  return Status::Ok();
}

Status ShardWriter::AddView(const ViewLabel& label, std::span<const PointQ> points) {
  THROW_CHECK_MSG(impl_->open, "ShardWriter::AddView before Open or after Finish");
  Impl& w = *impl_;
  const std::string where =
      w.file.target().string() + ": view " + std::to_string(w.view_table.size() / kViewRecordSize);
  if (label.flags != 0) {
    return Status(StatusCode::kNonZeroReserved, where + ": label.flags must be 0");
  }
  if (points.size() > UINT32_MAX) {
    return Status(StatusCode::kOutOfRange,
                  where + ": " + std::to_string(points.size()) + " points, more than 2^32-1");
  }
  if (!AllFinite(label)) {
    return Status(StatusCode::kOutOfRange, where + ": label has a non-finite value");
  }
  // Nothing the reader's open checks would refuse is written.
  std::array<uint8_t, kViewRecordSize> record{};
  EncodeViewRecord(label, 0, 0, record.data());
  ProblemList problems(w.file.target().string(), /*stop_at_first=*/true);
  CheckLabelRanges(
      record.data(), 0, w.view_table.size() / kViewRecordSize, nullptr, 0.0, "", &problems);
  if (!problems.empty()) {
    const Problem& p = problems.problems().front();
    return Status(p.code, w.file.target().string() + ": " + p.what);
  }
  for (size_t i = 0; i < points.size(); ++i) {
    if (std::abs(points[i].x) > kMaxAbsPointCoord || std::abs(points[i].y) > kMaxAbsPointCoord) {
      return Status(StatusCode::kOutOfRange,
                    where + ": point " + std::to_string(i) + " (" + std::to_string(points[i].x) +
                        ", " + std::to_string(points[i].y) + ") exceeds +-" +
                        std::to_string(kMaxAbsPointCoord) + " (1/16 px)");
    }
  }
  if (w.options.coded) {
    w.code.clear();
    HANDDB_RETURN_IF_ERROR(EncodeViewPoints(points, label.scale, label.source_centre_px, &w.code));
    HANDDB_RETURN_IF_ERROR(w.Append(w.code.data(), w.code.size()));
    w.points_hash.Update(w.code.data(), w.code.size());
    const size_t at = w.view_table.size();
    w.view_table.resize(at + kViewRecordSize);
    EncodeViewRecord(label, w.code_bytes, static_cast<uint32_t>(points.size()), &w.view_table[at]);
    w.code_bytes += w.code.size();
    w.num_points += points.size();
    std::array<uint8_t, kCoarseFieldSize> field;
    ComputeCoarseField(points, field.data());
    EncodeCoarseField(field, &w.field_codes);
    w.field_code_ends.push_back(w.field_codes.size());
    return Status::Ok();
  }
  const size_t bytes = points.size() * sizeof(PointQ);
  HANDDB_RETURN_IF_ERROR(w.Append(points.data(), bytes));
  w.points_hash.Update(points.data(), bytes);
  const size_t at = w.view_table.size();
  w.view_table.resize(at + kViewRecordSize);
  EncodeViewRecord(label, w.num_points, static_cast<uint32_t>(points.size()), &w.view_table[at]);
  w.num_points += points.size();
  if (w.options.coarse_fields) {
    const size_t c = w.coarse.size();
    w.coarse.resize(c + kCoarseFieldSize);
    ComputeCoarseField(points, &w.coarse[c]);
  }
  return Status::Ok();
}

Result<ShardSummary> ShardWriter::Finish() {
  THROW_CHECK_MSG(impl_->open, "ShardWriter::Finish before Open or twice");
  Impl& w = *impl_;
  w.open = false;
  const std::string& meta = w.options.metadata_json;
  std::vector<RawSection> sections;
  sections.push_back({kSectionMetadata,
                      kSectionFlagRequired,
                      w.metadata_offset,
                      meta.size(),
                      meta.size(),
                      1,
                      0,
                      Checksum(meta.data(), meta.size())});
  if (w.options.coded) {
    sections.push_back({kSectionPointCodes,
                        kSectionFlagRequired,
                        w.points_offset,
                        w.code_bytes,
                        w.code_bytes,
                        1,
                        0,
                        w.points_hash.Digest()});
  } else {
    sections.push_back({kSectionPoints,
                        kSectionFlagRequired,
                        w.points_offset,
                        w.num_points * kPointSize,
                        w.num_points,
                        kPointSize,
                        0,
                        w.points_hash.Digest()});
  }
  HANDDB_RETURN_IF_ERROR(w.PadTo64());
  const uint64_t num_views = w.view_table.size() / kViewRecordSize;
  sections.push_back({kSectionViews,
                      kSectionFlagRequired,
                      w.Position(),
                      w.view_table.size(),
                      num_views,
                      kViewRecordSize,
                      0,
                      Checksum(w.view_table.data(), w.view_table.size())});
  HANDDB_RETURN_IF_ERROR(w.Append(w.view_table.data(), w.view_table.size()));
  std::vector<uint8_t>().swap(w.view_table);
  if (w.options.coded) {
    // The offset table (num_views + 1 entries, relative to the section), then the codes.
    const uint64_t table_bytes = 8 * (num_views + 1);
    std::vector<uint8_t> table(table_bytes);
    StoreLittleEndian<uint64_t>(table.data(), table_bytes);
    for (uint64_t i = 0; i < num_views; ++i) {
      StoreLittleEndian<uint64_t>(table.data() + 8 * (i + 1), table_bytes + w.field_code_ends[i]);
    }
    StreamingChecksum hash;
    hash.Update(table.data(), table.size());
    hash.Update(w.field_codes.data(), w.field_codes.size());
    HANDDB_RETURN_IF_ERROR(w.PadTo64());
    const uint64_t size = table_bytes + w.field_codes.size();
    sections.push_back(
        {kSectionFieldCodes, kSectionFlagRequired, w.Position(), size, size, 1, 0, hash.Digest()});
    HANDDB_RETURN_IF_ERROR(w.Append(table.data(), table.size()));
    HANDDB_RETURN_IF_ERROR(w.Append(w.field_codes.data(), w.field_codes.size()));
    std::string().swap(w.field_codes);
  } else if (w.options.coarse_fields) {
    HANDDB_RETURN_IF_ERROR(w.PadTo64());
    sections.push_back({kSectionCoarseFields,
                        0,
                        w.Position(),
                        w.coarse.size(),
                        num_views,
                        kCoarseFieldSize,
                        0,
                        Checksum(w.coarse.data(), w.coarse.size())});
    HANDDB_RETURN_IF_ERROR(w.Append(w.coarse.data(), w.coarse.size()));
    std::vector<uint8_t>().swap(w.coarse);
  }
  for (const auto& extra : w.options.extra_sections) {
    HANDDB_RETURN_IF_ERROR(w.PadTo64());
    sections.push_back({extra.type,
                        extra.flags,
                        w.Position(),
                        extra.data.size(),
                        extra.data.size(),
                        1,
                        0,
                        Checksum(extra.data.data(), extra.data.size())});
    HANDDB_RETURN_IF_ERROR(w.Append(extra.data.data(), extra.data.size()));
  }
  HANDDB_RETURN_IF_ERROR(w.PadTo64());
  const uint64_t file_size = w.Position() + kFooterSize;
  uint8_t footer[kFooterSize];
  StoreLittleEndian<uint64_t>(footer, file_size);
  std::memcpy(footer + 8, kMagic.data(), 8);
  HANDDB_RETURN_IF_ERROR(w.Append(footer, sizeof(footer)));
  HANDDB_RETURN_IF_ERROR(w.Flush());

  std::vector<uint8_t> table(sections.size() * kSectionEntrySize);
  for (size_t i = 0; i < sections.size(); ++i) {
    sections[i].EncodeTo(&table[i * kSectionEntrySize]);
  }
  RawHeader h;
  h.magic = kMagic;
  h.version_major = kVersionMajor;
  h.version_minor = w.options.coded ? kVersionMinor : kVersionMinorPlain;
  h.required_features = w.options.coded ? kFeatureCodedViews : 0;
  h.header_size = kHeaderSize;
  h.file_size = file_size;
  h.num_views = num_views;
  h.num_points = w.num_points;
  h.section_table_offset = kHeaderSize;
  h.section_count = static_cast<uint32_t>(sections.size());
  h.section_entry_size = kSectionEntrySize;
  h.section_table_checksum = Checksum(table.data(), table.size());
  uint8_t header[kHeaderSize];
  h.EncodeTo(header);
  HANDDB_RETURN_IF_ERROR(w.file.WriteAt(0, header, sizeof(header)));
  HANDDB_RETURN_IF_ERROR(w.file.WriteAt(kHeaderSize, table.data(), table.size()));

  // The whole-file checksum (what the manifest lists and `xxhsum -H3` prints) needs the final
  // header, so the temp file is read back once; it is still in the page cache.
  Result<uint64_t> whole = FileChecksum(w.file.temp_path().string());
  if (!whole.ok()) return whole.status();
  HANDDB_RETURN_IF_ERROR(w.file.Commit());

  ShardSummary summary;
  summary.path = w.file.target();
  summary.num_views = num_views;
  summary.num_points = w.num_points;
  summary.file_size = file_size;
  summary.checksum = ChecksumHex(*whole);
  return summary;
}

}  // namespace handdb
