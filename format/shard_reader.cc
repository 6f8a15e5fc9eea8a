#include "format/shard_reader.h"

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "base/json_schema.h"
#include "base/mapped_file.h"
#include "format/coarse_field.h"
#include "format/field_codec.h"
#include "format/point_codec.h"
#include "format/shard_checks.h"
#include "format/shard_layout.h"

namespace handdb {

using namespace shard;  // NOLINT(google-build-using-namespace): the layout constants

struct ShardReader::Impl {
  std::string name;
  MappedFile file;              // empty when reading from memory
  std::vector<uint64_t> owned;  // aligned copy when FromMemory() got misaligned bytes
  std::span<const uint8_t> bytes;
  Layout layout;
  ShardHeaderInfo header;
  std::vector<SectionInfo> sections;
  const uint8_t* views = nullptr;
  uint64_t view_stride = kViewRecordSize;
  size_t num_views = 0;
  const PointQ* points = nullptr;
  uint64_t num_points = 0;
  std::string_view metadata;
  // Coded shards (v1.2): the two code sections.
  bool coded = false;
  std::span<const uint8_t> point_codes;
  std::span<const uint8_t> field_codes;

  const uint8_t* record(size_t i) const { return views + i * view_stride; }
  // View i's point code: from its offset to the next view's (checked at open).
  std::span<const uint8_t> point_code(size_t i) const {
    const uint64_t begin = LoadLittleEndian<uint64_t>(record(i) + kViewOffPointOffset);
    const uint64_t end = i + 1 < num_views
                             ? LoadLittleEndian<uint64_t>(record(i + 1) + kViewOffPointOffset)
                             : point_codes.size();
    return point_codes.subspan(begin, end - begin);
  }
  std::span<const uint8_t> field_code(size_t i) const {
    const uint64_t begin = LoadLittleEndian<uint64_t>(field_codes.data() + 8 * i);
    const uint64_t end = LoadLittleEndian<uint64_t>(field_codes.data() + 8 * (i + 1));
    return field_codes.subspan(begin, end - begin);
  }
  Status DecodeCodedPoints(size_t i, std::vector<PointQ>* out) const {
    const uint8_t* r = record(i);
    const std::span<const uint8_t> code = point_code(i);
    const Status s = DecodeViewPoints(code,
                                      LoadLittleEndian<float>(r + kViewOffScale),
                                      {LoadLittleEndian<float>(r + kViewOffSourceCentre),
                                       LoadLittleEndian<float>(r + kViewOffSourceCentre + 4)},
                                      out);
    const uint64_t at = static_cast<uint64_t>(code.data() - bytes.data());
    if (!s.ok()) {
      return Status(s.code(),
                    name + ": offset " + std::to_string(at) + ": view " + std::to_string(i) + ": " +
                        s.message());
    }
    const uint32_t want = LoadLittleEndian<uint32_t>(r + kViewOffPointCount);
    if (out->size() != want) {
      return Status(StatusCode::kSizeMismatch,
                    name + ": offset " + std::to_string(at) + ": view " + std::to_string(i) +
                        ": point code decodes to " + std::to_string(out->size()) +
                        " points, its record says " + std::to_string(want));
    }
    return Status::Ok();
  }
};

ShardReader::ShardReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ShardReader::~ShardReader() = default;
ShardReader::ShardReader(ShardReader&&) noexcept = default;
ShardReader& ShardReader::operator=(ShardReader&&) noexcept = default;

Result<ShardReader> ShardReader::Open(const std::filesystem::path& path) {
  auto impl = std::make_unique<Impl>();
  impl->name = path.string();
  auto file = MappedFile::Open(path);
  if (!file.ok()) return file.status();
  impl->file = std::move(file).value();
  impl->bytes = impl->file.bytes();
  return Init(std::move(impl));
}

Result<ShardReader> ShardReader::FromMemory(std::span<const uint8_t> bytes, std::string name) {
  auto impl = std::make_unique<Impl>();
  impl->name = std::move(name);
  if (reinterpret_cast<uintptr_t>(bytes.data()) % alignof(uint64_t) != 0) {
    // Spans of PointQ need aligned storage; misaligned input (fuzzers, sub-buffers) is copied.
    impl->owned.resize((bytes.size() + 7) / 8);
    if (!bytes.empty()) std::memcpy(impl->owned.data(), bytes.data(), bytes.size());
    impl->bytes = std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(impl->owned.data()),
                                           bytes.size());
  } else {
    impl->bytes = bytes;
  }
  return Init(std::move(impl));
}

Result<ShardReader> ShardReader::Init(std::unique_ptr<Impl> impl) {
  ProblemList problems(impl->name, /*stop_at_first=*/true);
  impl->layout = CheckLayout(impl->bytes, &problems);
  if (!problems.empty()) return problems.FirstStatus();
  THROW_CHECK(impl->layout.structure_ok && impl->layout.views_ok);
  const Layout& layout = impl->layout;
  const uint8_t* b = impl->bytes.data();
  const RawHeader& h = layout.header;
  impl->header.version_major = h.version_major;
  impl->header.version_minor = h.version_minor;
  impl->header.required_features = h.required_features;
  impl->header.optional_features = h.optional_features;
  impl->header.num_views = h.num_views;
  impl->header.num_points = h.num_points;
  impl->header.file_size = h.file_size;
  for (const RawSection& s : layout.sections) {
    SectionInfo info;
    info.type = s.type;
    info.flags = s.flags;
    info.offset = s.offset;
    info.size = s.size;
    info.count = s.count;
    info.element_size = s.element_size;
    info.checksum = s.checksum;
    info.name = SectionName(s.type);
    impl->sections.push_back(std::move(info));
  }
  const RawSection& meta = layout.sections[layout.metadata];
  impl->metadata = std::string_view(reinterpret_cast<const char*>(b + meta.offset),
                                    static_cast<size_t>(meta.size));
  // Every reader of the metadata (info, query, convert's keep check) parses and dumps it: refuse
  // nesting that would overflow their stacks, here once.
  if (Status s = CheckJsonDepth(
          impl->metadata,
          impl->name + ": metadata section at offset " + std::to_string(meta.offset));
      !s.ok()) {
    return s;
  }
  // The labels this reader returns are finite and in range (a NaN joint angle with recomputed
  // checksums would otherwise be served as `nan`).
  CheckViewLabels(impl->bytes, layout, &problems);
  if (!problems.empty()) return problems.FirstStatus();
  const RawSection& views = layout.sections[layout.views];
  impl->views = b + views.offset;
  impl->view_stride = views.element_size;
  impl->num_views = static_cast<size_t>(views.count);
  impl->coded = layout.coded;
  if (layout.coded) {
    const RawSection& pc = layout.sections[static_cast<size_t>(layout.point_codes)];
    const RawSection& fc = layout.sections[static_cast<size_t>(layout.field_codes)];
    impl->point_codes = impl->bytes.subspan(pc.offset, pc.size);
    impl->field_codes = impl->bytes.subspan(fc.offset, fc.size);
    impl->num_points = h.num_points;  // the records' counts add up to it (checked)
  } else {
    const RawSection& points = layout.sections[layout.points];
    impl->points = reinterpret_cast<const PointQ*>(b + points.offset);
    impl->num_points = points.count;
  }
  return ShardReader(std::move(impl));
}

Status ShardReader::VerifyChecksums() const {
  ProblemList problems(impl_->name, /*stop_at_first=*/true);
  CheckSectionChecksums(impl_->bytes, impl_->layout, &problems);
  return problems.FirstStatus();
}

const ShardHeaderInfo& ShardReader::header() const { return impl_->header; }
const std::vector<SectionInfo>& ShardReader::sections() const { return impl_->sections; }
std::string_view ShardReader::metadata_json() const { return impl_->metadata; }
const std::string& ShardReader::name() const { return impl_->name; }
size_t ShardReader::num_views() const { return impl_->num_views; }
std::span<const uint8_t> ShardReader::bytes() const { return impl_->bytes; }

std::span<const uint8_t> ShardReader::coarse_fields() const {
  const Layout& l = impl_->layout;
  if (l.coarse_fields < 0) return {};
  const RawSection& s = l.sections[static_cast<size_t>(l.coarse_fields)];
  return impl_->bytes.subspan(s.offset, s.size);
}

bool ShardReader::has_coarse_fields() const { return impl_->layout.coarse_fields >= 0; }

const uint8_t* ShardReader::coarse_field(size_t i) const {
  THROW_CHECK_LT(i, impl_->num_views);
  const std::span<const uint8_t> all = coarse_fields();
  return all.empty() ? nullptr : all.data() + i * kCoarseFieldSize;
}

namespace {

// Drops the mapped pages that lie wholly inside a section: the pages it shares with its
// neighbours stay.
void ReleaseSectionPages(const MappedFile& file, const RawSection& s) {
  constexpr uint64_t kPage = 4096;
  const uint64_t begin = (s.offset + kPage - 1) & ~(kPage - 1);
  const uint64_t end = std::min<uint64_t>(s.offset + s.size, file.size()) & ~(kPage - 1);
  file.Advise(begin, end, MappedFile::Advice::kDontNeed);
}

}  // namespace

void ShardReader::ReleaseViewTablePages() const {
  const Impl& r = *impl_;
  ReleaseSectionPages(r.file, r.layout.sections[r.layout.views]);
}

void ShardReader::ReleasePointCodePages() const {
  const Impl& r = *impl_;
  if (r.layout.point_codes < 0) return;
  ReleaseSectionPages(r.file, r.layout.sections[static_cast<size_t>(r.layout.point_codes)]);
}

void ShardReader::ReleaseCoarseFieldPages() const {
  const Impl& r = *impl_;
  if (r.layout.coarse_fields < 0) return;
  ReleaseSectionPages(r.file, r.layout.sections[static_cast<size_t>(r.layout.coarse_fields)]);
}

bool ShardReader::coded() const { return impl_->coded; }

uint32_t ShardReader::point_count(size_t i) const {
  THROW_CHECK_LT(i, impl_->num_views);
  return LoadLittleEndian<uint32_t>(impl_->record(i) + kViewOffPointCount);
}

std::span<const uint8_t> ShardReader::point_code(size_t i) const {
  THROW_CHECK_LT(i, impl_->num_views);
  return impl_->coded ? impl_->point_code(i) : std::span<const uint8_t>();
}

std::span<const uint8_t> ShardReader::field_code(size_t i) const {
  THROW_CHECK_LT(i, impl_->num_views);
  return impl_->coded ? impl_->field_code(i) : std::span<const uint8_t>();
}

Status ShardReader::DecodePoints(size_t i, std::vector<PointQ>* out) const {
  THROW_CHECK_LT(i, impl_->num_views);
  if (impl_->coded) return impl_->DecodeCodedPoints(i, out);
  const std::span<const PointQ> pts = points(i);
  out->assign(pts.begin(), pts.end());
  return Status::Ok();
}

Status ShardReader::PeekPoints(size_t i, ViewPointsExtent* extent) const {
  THROW_CHECK_LT(i, impl_->num_views);
  const Impl& r = *impl_;
  *extent = ViewPointsExtent{};
  if (!r.coded) return Status::Ok();
  const uint8_t* rec = r.record(i);
  const std::span<const uint8_t> code = r.point_code(i);
  const Status s = PeekViewPoints(code,
                                  LoadLittleEndian<float>(rec + kViewOffScale),
                                  {LoadLittleEndian<float>(rec + kViewOffSourceCentre),
                                   LoadLittleEndian<float>(rec + kViewOffSourceCentre + 4)},
                                  extent);
  const std::string where = r.name + ": offset " + std::to_string(code.data() - r.bytes.data()) +
                            ": view " + std::to_string(i) + ": ";
  if (!s.ok()) return Status(s.code(), where + s.message());
  const uint32_t want = LoadLittleEndian<uint32_t>(rec + kViewOffPointCount);
  if (extent->peeked && extent->count != want) {
    return Status(StatusCode::kSizeMismatch,
                  where + "point code holds " + std::to_string(extent->count) +
                      " points, its record says " + std::to_string(want));
  }
  return Status::Ok();
}

Status ShardReader::DecodeCoarseField(size_t i, uint8_t* out) const {
  THROW_CHECK_LT(i, impl_->num_views);
  const Impl& r = *impl_;
  if (!r.coded) {
    const uint8_t* field = coarse_field(i);
    if (field == nullptr) {
      return Status(StatusCode::kNotFound, r.name + ": has no coarse fields (a v1.0 shard)");
    }
    std::memcpy(out, field, kCoarseFieldSize);
    return Status::Ok();
  }
  const std::span<const uint8_t> code = r.field_code(i);
  const Status s = handdb::DecodeCoarseField(
      code, std::span<uint8_t, CoarseGrid::kCells>(out, kCoarseFieldSize));
  if (s.ok()) return s;
  return Status(s.code(),
                r.name + ": offset " + std::to_string(code.data() - r.bytes.data()) + ": view " +
                    std::to_string(i) + ": field code: " + s.message());
}

ViewLabel ShardReader::label(size_t i) const {
  THROW_CHECK_LT(i, impl_->num_views);
  return DecodeViewLabel(impl_->record(i));
}

uint64_t ShardReader::point_offset(size_t i) const {
  THROW_CHECK_LT(i, impl_->num_views);
  THROW_CHECK_MSG(!impl_->coded, impl_->name + ": a coded shard has no point offsets");
  return LoadLittleEndian<uint64_t>(impl_->record(i) + kViewOffPointOffset);
}

std::span<const PointQ> ShardReader::points(size_t i) const {
  THROW_CHECK_LT(i, impl_->num_views);
  THROW_CHECK_MSG(!impl_->coded,
                  impl_->name + ": a coded shard's points are decoded (ShardReader::DecodePoints)");
  const uint8_t* r = impl_->record(i);
  const uint64_t off = LoadLittleEndian<uint64_t>(r + kViewOffPointOffset);
  const uint32_t cnt = LoadLittleEndian<uint32_t>(r + kViewOffPointCount);
  return std::span<const PointQ>(impl_->points + off, cnt);  // range checked at open
}

std::span<const PointQ> ShardReader::all_points() const {
  if (impl_->coded) return {};
  return std::span<const PointQ>(impl_->points, static_cast<size_t>(impl_->num_points));
}

namespace {

// MADV_SEQUENTIAL on a mapped section for the duration of a scan: the kernel reads ahead
// aggressively on faults and drops pages behind. Measured (bench/format_bench): explicit
// MADV_WILLNEED / MADV_POPULATE_READ windows on top of this cost more CPU than the page faults they
// save on a warm cache (43% vs 59% of the raw read() rate).
class SequentialAdvice {
 public:
  SequentialAdvice(const MappedFile& file, uint64_t offset, uint64_t size)
      : file_(file), begin_(offset & ~uint64_t{4095}), end_(size == 0 ? begin_ : offset + size) {
    file_.Advise(begin_, end_, MappedFile::Advice::kSequential);
  }
  ~SequentialAdvice() { file_.Advise(begin_, end_, MappedFile::Advice::kNormal); }
  SequentialAdvice(const SequentialAdvice&) = delete;
  SequentialAdvice& operator=(const SequentialAdvice&) = delete;

 private:
  const MappedFile& file_;
  uint64_t begin_;
  uint64_t end_;
};

}  // namespace

Status ShardReader::ScanViews(const ViewCallback& fn, const ScanOptions& options) const {
  const Impl& r = *impl_;
  const Layout& layout = r.layout;
  const RawSection& vs = layout.sections[layout.views];
  // The data read in view order: the points, or a coded shard's point codes.
  const RawSection& ps =
      layout.sections[static_cast<size_t>(r.coded ? layout.point_codes : layout.points)];
  const uint8_t* base = r.bytes.data();
  const SequentialAdvice views_advice(r.file, vs.offset, vs.size);
  const SequentialAdvice points_advice(r.file, ps.offset, ps.size);
  StreamingChecksum views_hash;
  StreamingChecksum points_hash;
  std::vector<PointQ> decoded;
  for (size_t i = 0; i < r.num_views; ++i) {
    const uint8_t* rec = r.record(i);
    std::span<const PointQ> pts;
    if (r.coded) {
      const std::span<const uint8_t> code = r.point_code(i);
      if (options.verify_checksums) points_hash.Update(code.data(), code.size());
      HANDDB_RETURN_IF_ERROR(r.DecodeCodedPoints(i, &decoded));
      pts = decoded;
    } else {
      const uint64_t off = LoadLittleEndian<uint64_t>(rec + kViewOffPointOffset);
      const uint32_t cnt = LoadLittleEndian<uint32_t>(rec + kViewOffPointCount);
      pts = std::span<const PointQ>(r.points + off, cnt);
      if (options.verify_checksums) points_hash.Update(pts.data(), pts.size_bytes());
    }
    if (options.verify_checksums) views_hash.Update(rec, r.view_stride);
    HANDDB_RETURN_IF_ERROR(fn(i, DecodeViewLabel(rec), pts));
  }
  if (options.verify_checksums) {
    // Views cover the points (or codes) contiguously (checked at open), so these are the section
    // hashes.
    ProblemList problems(r.name, /*stop_at_first=*/true);
    auto compare = [&](const RawSection& s, uint64_t computed) {
      if (computed != s.checksum) {
        problems.Add("checksum",
                     StatusCode::kChecksumMismatch,
                     s.offset,
                     "section '" + SectionName(s.type) + "' [" + std::to_string(s.offset) + ", +" +
                         std::to_string(s.size) + "): checksum stored " + ChecksumHex(s.checksum) +
                         ", computed " + ChecksumHex(computed));
      }
    };
    compare(vs, views_hash.Digest());
    compare(ps, points_hash.Digest());
    if (!problems.empty()) return problems.FirstStatus();
    // The small sections (header, table, metadata, fields, unknown optional ones).
    for (const RawSection& s : layout.sections) {
      if (&s == &vs || &s == &ps) continue;
      compare(s, Checksum(base + s.offset, s.size));
      if (!problems.empty()) return problems.FirstStatus();
    }
  }
  return Status::Ok();
}

}  // namespace handdb
