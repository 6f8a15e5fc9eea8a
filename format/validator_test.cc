#include "format/validator.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "base/atomic_file.h"
#include "base/testing.h"
#include "format/manifest.h"
#include "format/shard_layout.h"
#include "format/shard_reader.h"
#include "format/shard_testing.h"

namespace handdb {
namespace {

using testing::ReadBytes;
using testing::TempDir;
using testing::WriteBytes;

namespace fs = std::filesystem;

std::vector<uint8_t> Sample(const std::string& name, uint32_t views = 6, bool coarse = true) {
  auto dir = TempDir(name);
  ShardWriterOptions options;
  options.coarse_fields = coarse;
  THROW_CHECK(testing::WriteSyntheticShard(dir / "s.hdb", views, 0, options).ok());
  auto bytes = ReadBytes(dir / "s.hdb");
  fs::remove_all(dir);
  return bytes;
}

uint64_t SectionOffset(const std::vector<uint8_t>& bytes, const std::string& name) {
  auto r = ShardReader::FromMemory(bytes, "s");
  THROW_CHECK(r.ok());
  for (const auto& s : r->sections()) {
    if (s.name == name) return s.offset;
  }
  THROW_CHECK_MSG(false, "no section " << name);
  return 0;
}

size_t Count(const ValidationReport& r, StatusCode code, const std::string& needle = "") {
  size_t n = 0;
  for (const auto& p : r.problems) {
    n += p.code == code && p.message.find(needle) != std::string::npos;
  }
  return n;
}

std::string Dump(const ValidationReport& r) {
  std::string out;
  for (const auto& p : r.problems)
    out += std::string(StatusCodeName(p.code)) + " " + p.message + "\n";
  return out;
}

TEST(Validator, AcceptsAGoodShard) {
  auto bytes = Sample("good");
  auto report = ValidateShardBytes(bytes, "good.hdb");
  EXPECT_TRUE(report.ok()) << Dump(report);
  EXPECT_EQ(report.files, 1u);
  EXPECT_EQ(report.views, 6u);
  EXPECT_GT(report.points, 0u);
}

TEST(Validator, ReportsEveryProblemWithOffsetAndRawValues) {
  auto bytes = Sample("many");
  const uint64_t views = SectionOffset(bytes, "views");
  const uint64_t points = SectionOffset(bytes, "points");
  // View 1: a joint angle beyond the hand model's limit [-0.5, 1.6]; view 2: NaN keypoint;
  // view 3: a non-unit view direction; points 0 and 7 out of range.
  const uint64_t joint_at = views + 1 * shard::kViewRecordSize + shard::kViewOffJointAngles + 4 * 6;
  shard::Store<float>(bytes.data() + joint_at, 2.5f);
  shard::Store<float>(
      bytes.data() + views + 2 * shard::kViewRecordSize + shard::kViewOffKeypoints + 12 * 4 + 4,
      std::nanf(""));
  shard::Store<float>(
      bytes.data() + views + 3 * shard::kViewRecordSize + shard::kViewOffViewDirection, 5.0f);
  shard::Store<int16_t>(bytes.data() + points, 7000);
  shard::Store<int16_t>(bytes.data() + points + 7 * 4 + 2, -6145);
  ASSERT_TRUE(shard::RewriteChecksums(bytes));
  // The reader opens it (the structure is fine) ...
  ASSERT_TRUE(ShardReader::FromMemory(bytes, "s").ok());
  // ... the validator finds all five problems, and that the moved points no longer match the
  // coarse fields stored for views 0 and 1.
  auto report = ValidateShardBytes(bytes, "bad.hdb");
  EXPECT_FALSE(report.ok());
  EXPECT_EQ(report.problems.size(), 7u) << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kOutOfRange), 7u) << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kOutOfRange, "view 0: coarse field cell"), 1u)
      << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kOutOfRange, "view 1: coarse field cell"), 1u)
      << Dump(report);
  EXPECT_EQ(Count(report,
                  StatusCode::kOutOfRange,
                  "bad.hdb: offset " + std::to_string(joint_at) +
                      ": view 1: joint_angles[6] = 2.5 rad is outside [-0.5, 1.6]"),
            1u)
      << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kOutOfRange, "view 2: keypoints[4][1] is nan"), 1u)
      << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kOutOfRange, "view 3: view_direction"), 1u) << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kOutOfRange, "view 0: point 0 (7000, "), 1u) << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kOutOfRange, "view 1: point 7 ("), 1u) << Dump(report);
}

// The coarse fields prune the search, so a wrong byte could hide a true match: the validator
// recomputes each view's field from its points, also when the checksums were recomputed.
TEST(Validator, CoarseFieldThatDisagreesWithItsPointsIsReported) {
  auto bytes = Sample("coarse");
  const uint64_t fields = SectionOffset(bytes, "coarse_fields");
  const uint64_t at = fields + 2 * shard::kCoarseFieldSize + 100;
  bytes[at] = static_cast<uint8_t>(bytes[at] + 1);
  ASSERT_TRUE(shard::RewriteChecksums(bytes));
  auto report = ValidateShardBytes(bytes, "c.hdb");
  EXPECT_EQ(report.problems.size(), 1u) << Dump(report);
  EXPECT_EQ(Count(report,
                  StatusCode::kOutOfRange,
                  "c.hdb: offset " + std::to_string(at) + ": view 2: coarse field cell 100 is"),
            1u)
      << Dump(report);
}

TEST(Validator, ReportsChecksumAndStructureProblemsTogether) {
  auto bytes = Sample("together");
  const uint64_t points = SectionOffset(bytes, "points");
  bytes[points + 1] ^= 0x40;             // points checksum
  bytes[shard::kOffHeaderReserved] = 1;  // reserved header byte (and header checksum)
  auto report = ValidateShardBytes(bytes, "t.hdb");
  EXPECT_EQ(Count(report, StatusCode::kChecksumMismatch, "'points'"), 1u) << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kChecksumMismatch, "header checksum"), 1u) << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kNonZeroReserved), 1u) << Dump(report);
}

TEST(Validator, CapsListedProblemsButCountsAll) {
  auto bytes = Sample("cap", 30, /*coarse=*/false);  // one problem per point, none per field
  const uint64_t points = SectionOffset(bytes, "points");
  auto reader = ShardReader::FromMemory(bytes, "s");
  ASSERT_TRUE(reader.ok());
  const size_t n = reader->all_points().size();
  for (size_t k = 0; k < n; ++k) shard::Store<int16_t>(bytes.data() + points + 4 * k, 9999);
  ASSERT_TRUE(shard::RewriteChecksums(bytes));
  ValidateOptions options;
  options.max_problems_per_check = 10;
  auto capped = ValidateShardBytes(bytes, "c.hdb", options);
  EXPECT_EQ(capped.problems.size(), 10u);
  EXPECT_EQ(capped.num_problems(), n);
  options.max_problems_per_check = 0;
  auto all = ValidateShardBytes(bytes, "c.hdb", options);
  EXPECT_EQ(all.problems.size(), n);
}

TEST(Validator, BadMetadataJson) {
  ShardWriterOptions options;
  options.metadata_json = R"({"hand_model": {"joint_limits": [[0, 1]]}})";
  auto dir = TempDir("meta");
  ASSERT_TRUE(testing::WriteSyntheticShard(dir / "m.hdb", 2, 0, options).ok());
  auto report = ValidateShardFile(dir / "m.hdb");
  EXPECT_EQ(Count(report, StatusCode::kSchemaViolation, "joint_limits"), 1u) << Dump(report);
  options.metadata_json = "{not json";
  ASSERT_TRUE(testing::WriteSyntheticShard(dir / "n.hdb", 2, 0, options).ok());
  report = ValidateShardFile(dir / "n.hdb");
  EXPECT_EQ(Count(report, StatusCode::kBadJson), 1u) << Dump(report);
  fs::remove_all(dir);
}

// Issue 14 item 2: metadata nested 100,000 deep overflowed the stack of every reader (info dumps
// it); the reader refuses it at open and validate reports it as one metadata problem.
TEST(Validator, DeeplyNestedMetadataIsRefused) {
  ShardWriterOptions options;
  options.metadata_json = "{\"a\": " + std::string(100000, '[') + std::string(100000, ']') + "}";
  auto dir = TempDir("deepmeta");
  ASSERT_TRUE(testing::WriteSyntheticShard(dir / "d.hdb", 2, 0, options).ok());
  auto report = ValidateShardFile(dir / "d.hdb");
  EXPECT_EQ(Count(report, StatusCode::kBadJson, "nested deeper than 64 levels"), 1u)
      << Dump(report);
  auto reader = ShardReader::Open(dir / "d.hdb");
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.status().code(), StatusCode::kBadJson);
  EXPECT_NE(reader.status().message().find("d.hdb: metadata section at offset "), std::string::npos)
      << reader.status().message();
  fs::remove_all(dir);
}

TEST(Validator, TruncatedFileIsReportedNotCrashed) {
  auto bytes = Sample("trunc");
  for (size_t len : {size_t{0}, size_t{5}, size_t{100}, bytes.size() / 2, bytes.size() - 1}) {
    std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + static_cast<ptrdiff_t>(len));
    auto report = ValidateShardBytes(prefix, "t.hdb");
    EXPECT_FALSE(report.ok()) << len;
    EXPECT_GE(Count(report, StatusCode::kTruncated), 1u) << len << "\n" << Dump(report);
  }
}

TEST(Validator, EveryBitFlipIsReported) {
  auto bytes = Sample("flips", 3);
  for (size_t bit = 0; bit < bytes.size() * 8; bit += 7) {
    bytes[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
    auto report = ValidateShardBytes(bytes, "f.hdb");
    bytes[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
    ASSERT_FALSE(report.ok()) << "bit " << bit;
  }
}

// A database of three shards and its manifest.
fs::path MakeDatabase(const std::string& name) {
  auto dir = TempDir(name);
  Manifest m;
  m.tool_version = "test";
  m.rolls = 48;
  for (uint32_t u = 0; u < 3; ++u) {
    char file[32];
    std::snprintf(file, sizeof(file), "shard-%05u.hdb", u);
    ShardWriter w;
    THROW_CHECK(w.Open(dir / file, {testing::SyntheticMetadata(), {}, true}).ok());
    for (uint32_t i = 0; i < 4; ++i) {
      const uint32_t id = u * 4 + i;
      THROW_CHECK(w.AddView(testing::SyntheticLabel(id), testing::SyntheticPoints(id, 9)).ok());
    }
    auto summary = w.Finish();
    THROW_CHECK(summary.ok());
    m.AddShard(*summary);
  }
  THROW_CHECK(WriteManifest(dir, m).ok());
  return dir;
}

TEST(Validator, AcceptsAGoodDatabase) {
  auto dir = MakeDatabase("db_good");
  auto report = ValidatePath(dir);
  EXPECT_TRUE(report.ok()) << Dump(report);
  EXPECT_EQ(report.files, 3u);
  EXPECT_EQ(report.views, 12u);
  fs::remove_all(dir);
}

TEST(Validator, ManifestAndShardsMustAgree) {
  auto dir = MakeDatabase("db_bad");
  // An unlisted shard, a missing one, one modified after the manifest was written.
  fs::copy_file(dir / "shard-00000.hdb", dir / "shard-00009.hdb");
  fs::remove(dir / "shard-00001.hdb");
  auto bytes = ReadBytes(dir / "shard-00002.hdb");
  bytes[SectionOffset(bytes, "points") + 3] ^= 1;
  WriteBytes(dir / "shard-00002.hdb", bytes);
  auto report = ValidatePath(dir);
  EXPECT_EQ(Count(report, StatusCode::kBadLayout, "shard-00009.hdb: shard file is not listed"), 1u)
      << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kNotFound, "shard-00001.hdb: listed in"), 1u) << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kChecksumMismatch, "whole-file xxh3"), 1u) << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kChecksumMismatch, "'points'"), 1u) << Dump(report);
  // The flipped bit moved view 0's first point away from what its coarse field was made from.
  EXPECT_EQ(Count(report, StatusCode::kOutOfRange, "view 0: coarse field"), 1u) << Dump(report);
  // shard-00009 is a copy of shard-00000 but unlisted, so it is not read: no duplicate ids.
  EXPECT_EQ(report.problems.size(), 5u) << Dump(report);
  fs::remove_all(dir);
}

TEST(Validator, DuplicateRenderIdsAcrossShards) {
  auto dir = MakeDatabase("db_dup");
  auto m = ReadManifest(dir);
  ASSERT_TRUE(m.ok());
  fs::copy_file(dir / "shard-00000.hdb", dir / "shard-00003.hdb");
  ShardSummary copy{dir / "shard-00003.hdb",
                    m->shards[0].views,
                    m->shards[0].points,
                    m->shards[0].bytes,
                    m->shards[0].xxh3};
  m->AddShard(copy);
  ASSERT_TRUE(WriteManifest(dir, *m).ok());
  auto report = ValidatePath(dir);
  EXPECT_EQ(Count(report, StatusCode::kBadLayout, "already appears in"), 4u) << Dump(report);
  fs::remove_all(dir);
}

TEST(Validator, MissingManifestStillChecksShards) {
  auto dir = MakeDatabase("db_nomanifest");
  fs::remove(dir / "manifest.json");
  auto report = ValidatePath(dir);
  EXPECT_EQ(report.problems.size(), 1u) << Dump(report);
  EXPECT_EQ(Count(report, StatusCode::kNotFound, "manifest.json"), 1u) << Dump(report);
  EXPECT_EQ(report.files, 3u);
  fs::remove_all(dir);
}

TEST(Validator, MissingPath) {
  auto report = ValidatePath("/nonexistent/handdb/shard.hdb");
  ASSERT_EQ(report.problems.size(), 1u);
  EXPECT_EQ(report.problems[0].code, StatusCode::kNotFound);
}

TEST(ValidateOptions, Check) {
  ValidateOptions good;
  EXPECT_TRUE(good.Check());
  ValidateOptions bad;
  bad.joint_limit_tolerance = -1;
  EXPECT_FALSE(bad.Check());
}

}  // namespace
}  // namespace handdb
