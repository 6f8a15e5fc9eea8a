#include "format/shard_reader.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <set>

#include "base/atomic_file.h"
#include "base/testing.h"
#include "format/coarse_field.h"
#include "format/shard_layout.h"
#include "format/shard_testing.h"
#include "format/shard_writer.h"
#include "format/validator.h"

namespace handdb {
namespace {

using testing::ReadBytes;
using testing::TempDir;

namespace fs = std::filesystem;

// A small sample shard as bytes (5 views, 5..9 points each).
std::vector<uint8_t> SampleShard(const std::string& name, ShardWriterOptions options = {}) {
  auto dir = TempDir(name);
  auto summary = testing::WriteSyntheticShard(dir / "s.hdb", 5, 0, std::move(options));
  THROW_CHECK_MSG(summary.ok(), summary.status().ToString());
  auto bytes = ReadBytes(dir / "s.hdb");
  fs::remove_all(dir);
  return bytes;
}

// Edits the header fields, then recomputes the header checksum (a well-formed file that says
// something this reader must refuse or accept).
void PatchHeader(std::vector<uint8_t>* bytes, size_t offset, const void* value, size_t size) {
  std::memcpy(bytes->data() + offset, value, size);
  ASSERT_TRUE(shard::RewriteChecksums(*bytes));
}

Status OpenAndVerify(std::span<const uint8_t> bytes) {
  auto reader = ShardReader::FromMemory(bytes, "sample.hdb");
  if (!reader.ok()) return reader.status();
  return reader->VerifyChecksums();
}

void ExpectSameLabel(const ViewLabel& a, const ViewLabel& b) {
  EXPECT_EQ(a.render_id, b.render_id);
  EXPECT_EQ(a.shape_id, b.shape_id);
  EXPECT_EQ(a.dir_id, b.dir_id);
  EXPECT_EQ(a.flags, b.flags);
  EXPECT_EQ(a.joint_angles, b.joint_angles);
  EXPECT_EQ(a.view_direction, b.view_direction);
  EXPECT_EQ(a.view_theta, b.view_theta);
  EXPECT_EQ(a.view_phi, b.view_phi);
  EXPECT_EQ(a.camera_roll, b.camera_roll);
  EXPECT_EQ(a.keypoints, b.keypoints);
  EXPECT_EQ(a.source_diameter_px, b.source_diameter_px);
  EXPECT_EQ(a.scale, b.scale);
  EXPECT_EQ(a.source_centre_px, b.source_centre_px);
}

TEST(ShardWriter, RoundTrip) {
  auto dir = TempDir("roundtrip");
  const uint32_t n = 40;
  auto summary = testing::WriteSyntheticShard(dir / "a.hdb", n);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_EQ(summary->num_views, n);
  EXPECT_EQ(summary->file_size, fs::file_size(dir / "a.hdb"));
  auto whole = shard::FileChecksum((dir / "a.hdb").string());
  ASSERT_TRUE(whole.ok());
  EXPECT_EQ(summary->checksum, shard::ChecksumHex(*whole));
  EXPECT_EQ(summary->checksum.size(), 16u);

  auto reader = ShardReader::Open(dir / "a.hdb");
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  ASSERT_TRUE(reader->VerifyChecksums().ok());
  EXPECT_EQ(reader->header().version_major, 1);
  EXPECT_EQ(reader->header().num_views, n);
  EXPECT_EQ(reader->header().file_size, summary->file_size);
  EXPECT_EQ(reader->metadata_json(), testing::SyntheticMetadata());
  ASSERT_EQ(reader->num_views(), n);
  uint64_t total = 0;
  for (uint32_t i = 0; i < n; ++i) {
    ExpectSameLabel(reader->label(i), testing::SyntheticLabel(i));
    auto expected = testing::SyntheticPoints(i, 5 + (i % 7));
    auto got = reader->points(i);
    ASSERT_EQ(got.size(), expected.size());
    for (size_t k = 0; k < got.size(); ++k) {
      EXPECT_EQ(got[k].x, expected[k].x);
      EXPECT_EQ(got[k].y, expected[k].y);
    }
    EXPECT_EQ(reader->point_offset(i), total);
    EXPECT_EQ(got.data(), reader->all_points().data() + total);  // zero-copy
    total += got.size();
  }
  EXPECT_EQ(reader->all_points().size(), total);
  EXPECT_EQ(summary->num_points, total);
  EXPECT_THROW((void)reader->label(n), std::logic_error);
  EXPECT_THROW((void)reader->points(n), std::logic_error);
  fs::remove_all(dir);
}

TEST(ShardWriter, SectionsAreAlignedAndInFileOrder) {
  auto bytes = SampleShard("aligned");
  auto reader = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  ASSERT_EQ(reader->sections().size(), 4u);
  uint64_t prev = 0;
  std::set<std::string> names;
  for (const auto& s : reader->sections()) {
    EXPECT_EQ(s.offset % 64, 0u) << s.name;
    EXPECT_GE(s.offset, prev);
    // The coarse fields are optional (a v1.0 reader skips them); the rest are required.
    EXPECT_EQ(s.flags & shard::kSectionFlagRequired,
              s.name == "coarse_fields" ? 0u : shard::kSectionFlagRequired);
    prev = s.offset + s.size;
    names.insert(s.name);
  }
  EXPECT_EQ(names, (std::set<std::string>{"metadata", "views", "points", "coarse_fields"}));
  EXPECT_EQ(reinterpret_cast<uintptr_t>(reader->all_points().data()) % 64,
            reinterpret_cast<uintptr_t>(bytes.data()) % 64);
}

TEST(ShardWriter, IsDeterministic) {
  auto dir = TempDir("determinism");
  ASSERT_TRUE(testing::WriteSyntheticShard(dir / "a.hdb", 30).ok());
  ASSERT_TRUE(testing::WriteSyntheticShard(dir / "b.hdb", 30).ok());
  EXPECT_EQ(ReadBytes(dir / "a.hdb"), ReadBytes(dir / "b.hdb"));
  fs::remove_all(dir);
}

TEST(ShardWriter, EmptyShardRoundTrips) {
  auto dir = TempDir("empty");
  auto summary = testing::WriteSyntheticShard(dir / "e.hdb", 0);
  ASSERT_TRUE(summary.ok());
  auto reader = ShardReader::Open(dir / "e.hdb");
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  EXPECT_EQ(reader->num_views(), 0u);
  EXPECT_TRUE(reader->all_points().empty());
  EXPECT_TRUE(reader->VerifyChecksums().ok());
  fs::remove_all(dir);
}

TEST(ShardWriter, RefusesBadViewsAndLeavesNoFile) {
  auto dir = TempDir("refuses");
  {
    ShardWriter w;
    ASSERT_TRUE(w.Open(dir / "x.hdb", {}).ok());
    std::vector<PointQ> bad = {{0, 0}, {6145, 0}};
    EXPECT_EQ(w.AddView(testing::SyntheticLabel(0), bad).code(), StatusCode::kOutOfRange);
    ViewLabel nan_label = testing::SyntheticLabel(1);
    nan_label.joint_angles[3] = std::nanf("");
    EXPECT_EQ(w.AddView(nan_label, testing::SyntheticPoints(1, 4)).code(), StatusCode::kOutOfRange);
    ViewLabel flagged = testing::SyntheticLabel(2);
    flagged.flags = 1;
    EXPECT_EQ(w.AddView(flagged, testing::SyntheticPoints(2, 4)).code(),
              StatusCode::kNonZeroReserved);
    ASSERT_TRUE(w.AddView(testing::SyntheticLabel(3), testing::SyntheticPoints(3, 4)).ok());
    // Destroyed without Finish(): nothing may be left behind.
  }
  EXPECT_TRUE(fs::is_empty(dir));
  fs::remove_all(dir);
}

TEST(ShardWriterOptions, Check) {
  ShardWriterOptions good;
  EXPECT_TRUE(good.Check());
  ShardWriterOptions bad;
  bad.extra_sections.push_back({shard::kSectionPoints, 0, "x"});
  EXPECT_FALSE(bad.Check());
}

TEST(ShardReader, FromMemoryMatchesPath) {
  auto dir = TempDir("memory");
  ASSERT_TRUE(testing::WriteSyntheticShard(dir / "a.hdb", 12).ok());
  auto bytes = ReadBytes(dir / "a.hdb");
  auto from_path = ShardReader::Open(dir / "a.hdb");
  auto from_memory = ShardReader::FromMemory(bytes, "a.hdb");
  ASSERT_TRUE(from_path.ok() && from_memory.ok());
  EXPECT_EQ(from_memory->name(), "a.hdb");
  ASSERT_EQ(from_path->num_views(), from_memory->num_views());
  for (size_t i = 0; i < from_path->num_views(); ++i) {
    ExpectSameLabel(from_path->label(i), from_memory->label(i));
    ASSERT_EQ(from_path->points(i).size(), from_memory->points(i).size());
  }
  // Misaligned memory is copied, not read through a misaligned PointQ*.
  std::vector<uint8_t> shifted(bytes.size() + 1);
  std::memcpy(shifted.data() + 1, bytes.data(), bytes.size());
  auto misaligned = ShardReader::FromMemory(std::span(shifted).subspan(1), "shifted.hdb");
  ASSERT_TRUE(misaligned.ok()) << misaligned.status().ToString();
  EXPECT_TRUE(misaligned->VerifyChecksums().ok());
  EXPECT_EQ(misaligned->points(3)[0].x, from_path->points(3)[0].x);
  fs::remove_all(dir);
}

TEST(ShardReader, LabelsReadBackAfterReleasingTheViewTablePages) {
  auto dir = TempDir("release");
  ASSERT_TRUE(testing::WriteSyntheticShard(dir / "a.hdb", 200).ok());  // an 80 KB view table
  auto bytes = ReadBytes(dir / "a.hdb");
  auto mapped = ShardReader::Open(dir / "a.hdb");
  auto memory = ShardReader::FromMemory(bytes, "a.hdb");
  ASSERT_TRUE(mapped.ok() && memory.ok());
  mapped->ReleaseViewTablePages();
  memory->ReleaseViewTablePages();  // no-op
  for (size_t i = 0; i < mapped->num_views(); ++i) {
    ExpectSameLabel(mapped->label(i), memory->label(i));
    ASSERT_EQ(mapped->point_offset(i), memory->point_offset(i));
  }
  EXPECT_TRUE(mapped->VerifyChecksums().ok());
  fs::remove_all(dir);
}

TEST(ShardReader, MissingFileAndDirectory) {
  auto dir = TempDir("missing");
  auto missing = ShardReader::Open(dir / "nope.hdb");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("nope.hdb"), std::string::npos);
  auto directory = ShardReader::Open(dir);
  ASSERT_FALSE(directory.ok());
  EXPECT_EQ(directory.status().code(), StatusCode::kIoError);
  ASSERT_TRUE(WriteFileAtomic(dir / "empty.hdb", "").ok());
  auto empty = ShardReader::Open(dir / "empty.hdb");
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.status().code(), StatusCode::kTruncated);
  fs::remove_all(dir);
}

TEST(ShardReader, RejectsBadMagic) {
  auto bytes = SampleShard("badmagic");
  bytes[1] = 'X';
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kBadMagic);
  EXPECT_NE(r.status().message().find("sample.hdb: offset 0"), std::string::npos);
  // A text file is not a shard either.
  std::string text = "{\"format\": \"handdb-manifest\"}\n";
  auto t = ShardReader::FromMemory(
      std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()), "manifest.json");
  ASSERT_FALSE(t.ok());
  EXPECT_EQ(t.status().code(), StatusCode::kBadMagic);
}

TEST(ShardReader, RejectsBadTrailingMagic) {
  auto bytes = SampleShard("badtrailer");
  bytes[bytes.size() - 1] ^= 0xff;
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kBadMagic);
  EXPECT_NE(r.status().message().find("trailing magic"), std::string::npos);
}

TEST(ShardReader, RejectsNewerMajorVersion) {
  auto bytes = SampleShard("major");
  const uint16_t major = 2;
  PatchHeader(&bytes, shard::kOffVersionMajor, &major, 2);
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kUnsupportedVersion);
  EXPECT_NE(r.status().message().find("version 2." + std::to_string(shard::kVersionMinorPlain)),
            std::string::npos)
      << r.status().message();
  const uint16_t zero = 0;
  PatchHeader(&bytes, shard::kOffVersionMajor, &zero, 2);
  EXPECT_EQ(ShardReader::FromMemory(bytes, "s").status().code(), StatusCode::kUnsupportedVersion);
}

TEST(ShardReader, AcceptsNewerMinorVersion) {
  auto bytes = SampleShard("minor");
  const uint16_t minor = 7;
  PatchHeader(&bytes, shard::kOffVersionMinor, &minor, 2);
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->header().version_minor, 7);
  EXPECT_TRUE(r->VerifyChecksums().ok());
}

TEST(ShardReader, RefusesUnknownRequiredFeatureBit) {
  auto bytes = SampleShard("reqbit");
  const uint64_t bit = uint64_t{1} << 5;
  PatchHeader(&bytes, shard::kOffRequiredFeatures, &bit, 8);
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kUnknownRequiredFeature);
  EXPECT_NE(r.status().message().find("0x20"), std::string::npos);
}

TEST(ShardReader, IgnoresUnknownOptionalFeatureBit) {
  auto bytes = SampleShard("optbit");
  const uint64_t bits = 0xf0f0;
  PatchHeader(&bytes, shard::kOffOptionalFeatures, &bits, 8);
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->header().optional_features, 0xf0f0u);
}

TEST(ShardReader, SkipsUnknownOptionalSection) {
  ShardWriterOptions options;
  options.extra_sections.push_back({0x7777, 0, "a section from a future minor version"});
  auto bytes = SampleShard("optsection", options);
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->sections().size(), 5u);
  EXPECT_EQ(r->sections()[4].name, "unknown(0x7777)");
  EXPECT_TRUE(r->VerifyChecksums().ok());
  EXPECT_EQ(r->num_views(), 5u);
  ExpectSameLabel(r->label(4), testing::SyntheticLabel(4));
  // Its bytes are still checksummed.
  bytes[r->sections()[4].offset + 2] ^= 1;
  EXPECT_EQ(OpenAndVerify(bytes).code(), StatusCode::kChecksumMismatch);
}

// v1.1: one coarse field per view, equal to the one computed from its points; a shard written
// without (or a v1.0 shard) has none and still opens; a count that disagrees is refused.
TEST(ShardReader, CoarseFieldsSection) {
  auto bytes = SampleShard("coarse");
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->header().version_minor, 1);
  ASSERT_TRUE(r->has_coarse_fields());
  EXPECT_EQ(r->coarse_fields().size(), 5u * shard::kCoarseFieldSize);
  for (size_t i = 0; i < r->num_views(); ++i) {
    std::vector<uint8_t> want(shard::kCoarseFieldSize);
    ComputeCoarseField(r->points(i), want.data());
    EXPECT_EQ(std::vector<uint8_t>(r->coarse_field(i), r->coarse_field(i) + want.size()), want)
        << "view " << i;
  }

  ShardWriterOptions without;
  without.coarse_fields = false;
  auto plain = SampleShard("nocoarse", without);
  auto p = ShardReader::FromMemory(plain, "plain.hdb");
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_FALSE(p->has_coarse_fields());
  EXPECT_EQ(p->coarse_field(0), nullptr);
  EXPECT_EQ(p->sections().size(), 3u);

  // The section's count says 4 fields for 5 views (size and table checksum made consistent).
  for (const auto& s : r->sections()) {
    if (s.name != "coarse_fields") continue;
    const size_t table = shard::kHeaderSize;
    for (size_t e = 0; e < r->sections().size(); ++e) {
      const size_t at = table + e * shard::kSectionEntrySize;
      if (LoadLittleEndian<uint32_t>(bytes.data() + at) != shard::kSectionCoarseFields) continue;
      StoreLittleEndian<uint64_t>(bytes.data() + at + shard::kSecOffCount, 4);
      StoreLittleEndian<uint64_t>(bytes.data() + at + shard::kSecOffSize,
                                  4 * shard::kCoarseFieldSize);
    }
  }
  ASSERT_TRUE(shard::RewriteChecksums(bytes));
  auto bad = ShardReader::FromMemory(bytes, "bad.hdb");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("coarse_fields"), std::string::npos)
      << bad.status().message();
}

TEST(ShardReader, RefusesUnknownRequiredSection) {
  ShardWriterOptions options;
  options.extra_sections.push_back({0x7777, shard::kSectionFlagRequired, "must understand"});
  auto bytes = SampleShard("reqsection", options);
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kUnknownRequiredFeature);
  EXPECT_NE(r.status().message().find("0x7777"), std::string::npos);
}

TEST(ShardReader, RejectsNonZeroReserved) {
  auto bytes = SampleShard("reserved");
  const uint8_t one = 1;
  PatchHeader(&bytes, shard::kOffHeaderReserved + 3, &one, 1);
  EXPECT_EQ(ShardReader::FromMemory(bytes, "s").status().code(), StatusCode::kNonZeroReserved);
  // Padding between sections must be zero too (not checksummed, so checked at open).
  auto padded = SampleShard("padding");
  auto r = ShardReader::FromMemory(padded, "s");
  ASSERT_TRUE(r.ok());
  const auto& meta = r->sections()[0];
  ASSERT_EQ(meta.name, "metadata");
  ASSERT_NE((meta.offset + meta.size) % 64, 0u);
  padded[meta.offset + meta.size] = 0x20;
  EXPECT_EQ(ShardReader::FromMemory(padded, "s").status().code(), StatusCode::kNonZeroReserved);
}

TEST(ShardReader, RejectsViewPointsOutsidePointsSection) {
  auto bytes = SampleShard("viewrange");
  auto r = ShardReader::FromMemory(bytes, "s");
  ASSERT_TRUE(r.ok());
  uint64_t views_offset = 0;
  for (const auto& s : r->sections()) {
    if (s.name == "views") views_offset = s.offset;
  }
  // A count that would run past the points section, with every checksum made consistent.
  const uint32_t huge = 0xfffffff0u;
  std::memcpy(bytes.data() + views_offset + 4 * shard::kViewRecordSize + shard::kViewOffPointCount,
              &huge,
              4);
  ASSERT_TRUE(shard::RewriteChecksums(bytes));
  auto bad = ShardReader::FromMemory(bytes, "s");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kOutOfRange);
  EXPECT_NE(bad.status().message().find("view 4"), std::string::npos);
}

// A shard whose checksums were recomputed over a NaN joint angle or an infinite keypoint would
// open and be queried, printing `nan` / JSON null. The open checks range-check every
// label, with one line naming the shard, the offset, the view and the field.
TEST(ShardReader, RefusesLabelsOutOfRange) {
  const auto good = SampleShard("labels");
  auto r = ShardReader::FromMemory(good, "s");
  ASSERT_TRUE(r.ok());
  uint64_t views = 0;
  for (const auto& s : r->sections()) {
    if (s.name == "views") views = s.offset;
  }
  struct Case {
    size_t field;  // offset inside view 3's record
    float value;
    std::string message;
  };
  const uint64_t rec = views + 3 * shard::kViewRecordSize;
  const std::vector<Case> cases = {
      {shard::kViewOffJointAngles + 4 * 2,
       std::nanf(""),
       "view 3: joint_angles[2] is nan (not finite)"},
      {shard::kViewOffKeypoints + 12 * 5 + 4,
       std::numeric_limits<float>::infinity(),
       "view 3: keypoints[5][1] is inf (not finite)"},
      {shard::kViewOffJointAngles + 4 * 7,
       7.0f,
       "view 3: joint_angles[7] = 7 rad is outside [-6.28318531, 6.28318531] (no hand model: "
       "+-2 pi)"},
      {shard::kViewOffKeypoints + 12 * 20, -500.0f, "view 3: keypoint 20 (-500, "},
      {shard::kViewOffCameraRoll, 9.0f, "view 3: camera_roll is 9 rad, outside [-2 pi, 2 pi]"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.message);
    auto bytes = good;
    StoreLittleEndian<float>(bytes.data() + rec + c.field, c.value);
    ASSERT_TRUE(shard::RewriteChecksums(bytes));
    auto bad = ShardReader::FromMemory(bytes, "bad.hdb");
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.status().code(), StatusCode::kOutOfRange);
    const std::string& m = bad.status().message();
    const std::string prefix = "bad.hdb: offset " + std::to_string(rec + c.field) + ": ";
    EXPECT_EQ(m.rfind(prefix + c.message, 0), 0u) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
  auto bytes = good;
  StoreLittleEndian<uint32_t>(bytes.data() + rec + shard::kViewOffShapeId, kInvalidShapeId);
  ASSERT_TRUE(shard::RewriteChecksums(bytes));
  EXPECT_EQ(ShardReader::FromMemory(bytes, "bad.hdb").status().message(),
            "bad.hdb: offset " + std::to_string(rec) +
                ": view 3: shape_id is 0xffffffff (the invalid id: never filled in)");
}

TEST(ShardWriter, RefusesLabelsTheReaderWouldRefuse) {
  auto dir = TempDir("writer-ranges");
  ShardWriter w;
  ASSERT_TRUE(w.Open(dir / "x.hdb", {}).ok());
  ViewLabel far = testing::SyntheticLabel(0);
  far.keypoints[2][0] = 400.0f;
  const Status s = w.AddView(far, testing::SyntheticPoints(0, 4));
  EXPECT_EQ(s.code(), StatusCode::kOutOfRange);
  EXPECT_EQ(s.message().rfind((dir / "x.hdb").string() + ": view 0: keypoint 2 (400, ", 0), 0u)
      << s.message();
  fs::remove_all(dir);
}

TEST(ShardReader, RejectsTrailingBytes) {
  auto bytes = SampleShard("trailing");
  bytes.push_back(0);
  EXPECT_EQ(ShardReader::FromMemory(bytes, "s").status().code(), StatusCode::kSizeMismatch);
}

TEST(ShardReader, EveryTruncationFailsCleanly) {
  const auto bytes = SampleShard("truncation");
  ASSERT_TRUE(OpenAndVerify(bytes).ok());
  for (size_t len = 0; len < bytes.size(); ++len) {
    // A fresh exact-size heap copy so ASan sees any read past the end.
    std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + static_cast<ptrdiff_t>(len));
    auto r = ShardReader::FromMemory(prefix, "t.hdb");
    ASSERT_FALSE(r.ok()) << "truncated to " << len << " bytes was accepted";
    const StatusCode code = r.status().code();
    EXPECT_TRUE(code == StatusCode::kTruncated || code == StatusCode::kBadMagic) << len;
  }
}

// Flips one bit, checks open + VerifyChecksums fails, flips it back.
void ExpectFlipDetected(std::vector<uint8_t>* bytes, size_t bit, std::set<StatusCode>* codes) {
  (*bytes)[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
  Status s = OpenAndVerify(*bytes);
  (*bytes)[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
  ASSERT_FALSE(s.ok()) << "bit " << bit << " (byte " << bit / 8 << ") flipped, still valid";
  EXPECT_FALSE(s.message().empty());
  codes->insert(s.code());
}

TEST(ShardReader, EverySingleBitFlipIsDetected) {
  auto bytes = SampleShard("everybit", {"{}", {}, true});
  std::set<StatusCode> codes;
  for (size_t bit = 0; bit < bytes.size() * 8; ++bit) {
    ExpectFlipDetected(&bytes, bit, &codes);
    if (HasFatalFailure()) return;
  }
  EXPECT_TRUE(codes.count(StatusCode::kChecksumMismatch));
  EXPECT_TRUE(codes.count(StatusCode::kBadMagic));
  EXPECT_TRUE(codes.count(StatusCode::kNonZeroReserved));
}

TEST(ShardReader, RandomSingleBitFlipsAreDetected) {
  auto dir = TempDir("flips");
  ASSERT_TRUE(testing::WriteSyntheticShard(dir / "f.hdb", 64, 40).ok());
  auto bytes = ReadBytes(dir / "f.hdb");
  fs::remove_all(dir);
  std::mt19937_64 rng(20010901);
  std::uniform_int_distribution<size_t> pick(0, bytes.size() * 8 - 1);
  std::set<StatusCode> codes;
  for (int trial = 0; trial < 10000; ++trial) {
    ExpectFlipDetected(&bytes, pick(rng), &codes);
    if (HasFatalFailure()) return;
  }
  EXPECT_TRUE(OpenAndVerify(bytes).ok());  // every flip was undone
}

TEST(ShardReader, VerifyChecksumsNamesTheSection) {
  auto bytes = SampleShard("names");
  auto r = ShardReader::FromMemory(bytes, "sample.hdb");
  ASSERT_TRUE(r.ok());
  const SectionInfo* points = nullptr;
  for (const auto& s : r->sections()) {
    if (s.name == "points") points = &s;
  }
  ASSERT_NE(points, nullptr);
  bytes[points->offset + 5] ^= 0x10;
  Status s = r->VerifyChecksums();  // the reader maps `bytes`, so it sees the change
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kChecksumMismatch);
  EXPECT_NE(s.message().find("'points'"), std::string::npos);
  EXPECT_NE(s.message().find("offset " + std::to_string(points->offset)), std::string::npos);
}

TEST(ShardReader, ScanViewsVisitsEveryViewInOrder) {
  auto dir = TempDir("scan");
  ASSERT_TRUE(testing::WriteSyntheticShard(dir / "s.hdb", 25).ok());
  auto r = ShardReader::Open(dir / "s.hdb");
  ASSERT_TRUE(r.ok());
  size_t next = 0;
  uint64_t points = 0;
  Status s = r->ScanViews(
      [&](size_t i, const ViewLabel& label, std::span<const PointQ> pts) {
        EXPECT_EQ(i, next++);
        EXPECT_EQ(label.render_id, i);
        EXPECT_EQ(pts.data(), r->points(i).data());
        points += pts.size();
        return Status::Ok();
      },
      {.verify_checksums = true});
  EXPECT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(next, 25u);
  EXPECT_EQ(points, r->all_points().size());
  // The callback's error stops the scan.
  next = 0;
  s = r->ScanViews([&](size_t i, const ViewLabel&, std::span<const PointQ>) {
    ++next;
    return i == 3 ? Status(StatusCode::kCancelled, "stop") : Status::Ok();
  });
  EXPECT_EQ(s.code(), StatusCode::kCancelled);
  EXPECT_EQ(next, 4u);
  fs::remove_all(dir);
}

TEST(ShardReader, ScanWithVerificationDetectsCorruptPoints) {
  auto bytes = SampleShard("scanverify");
  auto r = ShardReader::FromMemory(bytes, "s");
  ASSERT_TRUE(r.ok());
  bytes[r->sections()[1].offset] ^= 4;  // points (file order: metadata, points, views)
  ASSERT_EQ(r->sections()[1].name, "points");
  Status s =
      r->ScanViews([](size_t, const ViewLabel&, std::span<const PointQ>) { return Status::Ok(); },
                   {.verify_checksums = true});
  EXPECT_EQ(s.code(), StatusCode::kChecksumMismatch);
}

}  // namespace
}  // namespace handdb

namespace handdb {
namespace {

// A coded shard (v1.2): 6 converted-like views on the render lattice, one off it (delta code),
// one empty.
struct CodedSample {
  std::vector<ViewLabel> labels;
  std::vector<std::vector<PointQ>> points;
  std::vector<uint8_t> bytes;
};

// File offset of the (first) section of `type`.
uint64_t SectionOffset(const std::vector<uint8_t>& bytes, uint32_t type) {
  const shard::RawHeader h = shard::RawHeader::DecodeFrom(bytes);
  for (uint32_t i = 0; i < h.section_count; ++i) {
    const shard::RawSection s = shard::RawSection::DecodeFrom(
        bytes.data() + h.section_table_offset + i * h.section_entry_size);
    if (s.type == type) return s.offset;
  }
  THROW_CHECK_MSG(false, "no section of type " << type);
  return 0;
}

CodedSample MakeCodedSample(const std::string& name, bool coded = true) {
  CodedSample c;
  for (uint32_t i = 0; i < 8; ++i) {
    c.labels.push_back(testing::SyntheticLabel(i));
    if (i == 6) {
      c.points.push_back(testing::SyntheticPoints(i, 50));  // unsorted, off the lattice
    } else if (i == 7) {
      c.points.emplace_back();
    } else {
      c.points.push_back(testing::LatticePoints(c.labels.back(), i));
    }
  }
  auto dir = TempDir(name);
  ShardWriterOptions options;
  options.metadata_json = testing::SyntheticMetadata();
  options.coded = coded;
  ShardWriter writer;
  THROW_CHECK(writer.Open(dir / "s.hdb", options).ok());
  for (size_t i = 0; i < c.labels.size(); ++i) {
    THROW_CHECK(writer.AddView(c.labels[i], c.points[i]).ok());
  }
  THROW_CHECK(writer.Finish().ok());
  c.bytes = ReadBytes(dir / "s.hdb");
  fs::remove_all(dir);
  return c;
}

TEST(CodedShard, RoundTripsPointsFieldsAndLabels) {
  const CodedSample c = MakeCodedSample("coded_rt");
  const CodedSample plain = MakeCodedSample("coded_rt_plain", /*coded=*/false);
  EXPECT_LT(c.bytes.size() * 2, plain.bytes.size())
      << c.bytes.size() << " vs " << plain.bytes.size();
  auto r = ShardReader::FromMemory(c.bytes, "coded.hdb");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->coded());
  EXPECT_EQ(r->header().version_minor, shard::kVersionMinor);
  EXPECT_EQ(r->header().required_features, shard::kFeatureCodedViews);
  EXPECT_TRUE(r->VerifyChecksums().ok());
  EXPECT_TRUE(r->all_points().empty());
  EXPECT_FALSE(r->has_coarse_fields());
  uint64_t total = 0;
  std::vector<PointQ> pts;
  for (size_t i = 0; i < c.labels.size(); ++i) {
    ASSERT_TRUE(r->DecodePoints(i, &pts).ok());
    ASSERT_EQ(pts.size(), c.points[i].size()) << i;
    EXPECT_EQ(r->point_count(i), c.points[i].size());
    for (size_t k = 0; k < pts.size(); ++k) {
      ASSERT_TRUE(pts[k].x == c.points[i][k].x && pts[k].y == c.points[i][k].y) << i << " " << k;
    }
    total += pts.size();
    std::array<uint8_t, shard::kCoarseFieldSize> field{}, want{};
    ASSERT_TRUE(r->DecodeCoarseField(i, field.data()).ok());
    ComputeCoarseField(c.points[i], want.data());
    EXPECT_EQ(field, want) << i;
    const ViewLabel l = r->label(i);
    EXPECT_EQ(l.render_id, c.labels[i].render_id);
    EXPECT_EQ(l.scale, c.labels[i].scale);
  }
  EXPECT_EQ(r->header().num_points, total);
  EXPECT_THROW(r->points(0), std::exception);
  // The plain shard of the same views gives the same through the same calls.
  auto p = ShardReader::FromMemory(plain.bytes, "plain.hdb");
  ASSERT_TRUE(p.ok());
  EXPECT_FALSE(p->coded());
  ASSERT_TRUE(p->DecodePoints(2, &pts).ok());
  EXPECT_EQ(pts.size(), c.points[2].size());
  EXPECT_TRUE(p->point_code(2).empty());
  // ScanViews decodes, and its checksum pass covers the code sections.
  size_t seen = 0;
  ScanOptions scan;
  scan.verify_checksums = true;
  const Status s = r->ScanViews(
      [&](size_t i, const ViewLabel&, std::span<const PointQ> v) {
        EXPECT_EQ(v.size(), c.points[i].size());
        ++seen;
        return Status::Ok();
      },
      scan);
  EXPECT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(seen, c.labels.size());
}

TEST(CodedShard, IsDeterministic) {
  EXPECT_EQ(MakeCodedSample("coded_det1").bytes, MakeCodedSample("coded_det2").bytes);
}

TEST(CodedShard, WithoutTheFeatureBitIsRefused) {
  CodedSample c = MakeCodedSample("coded_nobit");
  const uint64_t none = 0;
  PatchHeader(&c.bytes, shard::kOffRequiredFeatures, &none, 8);
  auto r = ShardReader::FromMemory(c.bytes, "coded.hdb");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("no 'points' section"), std::string::npos)
      << r.status().ToString();
  // And a plain shard that claims the bit has no point codes.
  CodedSample plain = MakeCodedSample("coded_bit_plain", false);
  const uint64_t bit = shard::kFeatureCodedViews;
  PatchHeader(&plain.bytes, shard::kOffRequiredFeatures, &bit, 8);
  auto q = ShardReader::FromMemory(plain.bytes, "plain.hdb");
  ASSERT_FALSE(q.ok());
  EXPECT_NE(q.status().message().find("has the coded-views bit"), std::string::npos)
      << q.status().ToString();
}

TEST(CodedShard, DamagedCodesAreErrorsNamingTheView) {
  const CodedSample c = MakeCodedSample("coded_damage");
  auto r0 = ShardReader::FromMemory(c.bytes, "coded.hdb");
  ASSERT_TRUE(r0.ok());
  // Flip bits inside view 3's point code and field code with recomputed checksums: the open
  // checks pass (they do not decode), decoding names the view, the validator finds both.
  const uint64_t code_at = static_cast<uint64_t>(r0->point_code(3).data() - r0->bytes().data());
  const uint64_t field_at = static_cast<uint64_t>(r0->field_code(3).data() - r0->bytes().data());
  int point_errors = 0;
  int field_errors = 0;
  for (uint64_t k = 1; k < r0->point_code(3).size(); k += 7) {
    for (const bool field : {false, true}) {
      std::vector<uint8_t> bytes = c.bytes;
      const uint64_t at = (field ? field_at : code_at) + k;
      if (field && k >= r0->field_code(3).size()) continue;
      bytes[at] ^= 0x5a;
      ASSERT_TRUE(shard::RewriteChecksums(bytes));
      auto r = ShardReader::FromMemory(bytes, "coded.hdb");
      ASSERT_TRUE(r.ok()) << r.status().ToString();
      std::vector<PointQ> pts;
      std::array<uint8_t, shard::kCoarseFieldSize> f{};
      const Status s = field ? r->DecodeCoarseField(3, f.data()) : r->DecodePoints(3, &pts);
      const ValidationReport report = ValidateShardBytes(bytes, "coded.hdb", {});
      if (!s.ok()) {
        EXPECT_NE(s.message().find("coded.hdb: offset"), std::string::npos) << s.ToString();
        EXPECT_NE(s.message().find("view 3"), std::string::npos) << s.ToString();
        EXPECT_FALSE(report.ok()) << "validator missed " << s.ToString();
        (field ? field_errors : point_errors)++;
      } else {
        // A damaged code may still decode (to other points or another field): then the
        // validator's field check or count check catches it unless the bytes coded the same.
        std::vector<PointQ> want = c.points[3];
        if (!field && pts.size() == want.size() &&
            std::equal(pts.begin(), pts.end(), want.begin(), [](PointQ a, PointQ b) {
              return a.x == b.x && a.y == b.y;
            })) {
          continue;
        }
        std::array<uint8_t, shard::kCoarseFieldSize> want_field{};
        ComputeCoarseField(c.points[3], want_field.data());
        if (field && f == want_field) continue;
        EXPECT_FALSE(report.ok()) << (field ? "field" : "points") << " byte " << k;
      }
    }
  }
  EXPECT_GT(point_errors, 0);
  EXPECT_GT(field_errors, 0);
}

TEST(CodedShard, ValidatorAcceptsAGoodOne) {
  const CodedSample c = MakeCodedSample("coded_valid");
  const ValidationReport report = ValidateShardBytes(c.bytes, "coded.hdb", {});
  EXPECT_TRUE(report.ok()) << (report.problems.empty() ? "" : report.problems[0].message);
  EXPECT_EQ(report.views, c.labels.size());
}

TEST(CodedShard, BadOffsetsAreRefusedAtOpen) {
  const CodedSample c = MakeCodedSample("coded_offsets");
  auto r0 = ShardReader::FromMemory(c.bytes, "coded.hdb");
  ASSERT_TRUE(r0.ok());
  // View 2's point code offset moved before view 1's.
  {
    std::vector<uint8_t> bytes = c.bytes;
    const uint64_t rec = SectionOffset(c.bytes, shard::kSectionViews) + 2 * shard::kViewRecordSize;
    StoreLittleEndian<uint64_t>(bytes.data() + rec + shard::kViewOffPointOffset, 1);
    ASSERT_TRUE(shard::RewriteChecksums(bytes));
    auto r = ShardReader::FromMemory(bytes, "coded.hdb");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("view 2: point code offset"), std::string::npos)
        << r.status().ToString();
  }
  // A field code offset past the section.
  {
    std::vector<uint8_t> bytes = c.bytes;
    const uint64_t table = SectionOffset(c.bytes, shard::kSectionFieldCodes);
    StoreLittleEndian<uint64_t>(bytes.data() + table + 8 * 4, uint64_t{1} << 40);
    ASSERT_TRUE(shard::RewriteChecksums(bytes));
    auto r = ShardReader::FromMemory(bytes, "coded.hdb");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("field_codes offset 4"), std::string::npos)
        << r.status().ToString();
  }
}

}  // namespace
}  // namespace handdb
