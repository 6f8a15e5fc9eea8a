#include "format/validator.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

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
  StoreLittleEndian<float>(bytes.data() + joint_at, 2.5f);
  StoreLittleEndian<float>(
      bytes.data() + views + 2 * shard::kViewRecordSize + shard::kViewOffKeypoints + 12 * 4 + 4,
      std::nanf(""));
  StoreLittleEndian<float>(
      bytes.data() + views + 3 * shard::kViewRecordSize + shard::kViewOffViewDirection, 5.0f);
  StoreLittleEndian<int16_t>(bytes.data() + points, 7000);
  StoreLittleEndian<int16_t>(bytes.data() + points + 7 * 4 + 2, -6145);
  ASSERT_TRUE(shard::RewriteChecksums(bytes));
  // The reader refuses it at the first problem (view 2's NaN: view 1's joint is inside +-2 pi,
  // the reader knows no hand model) ...
  EXPECT_NE(ShardReader::FromMemory(bytes, "s")
                .status()
                .message()
                .find("view 2: keypoints[4][1] is nan (not finite)"),
            std::string::npos);
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
  for (size_t k = 0; k < n; ++k) StoreLittleEndian<int16_t>(bytes.data() + points + 4 * k, 9999);
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

// Metadata nested 100,000 deep would overflow the stack of every reader (info dumps it); the
// reader refuses it at open and validate reports it as one metadata problem.
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
// Shard u of a test database: synthetic views u*4 .. u*4+3 of 9 points, with `metadata`.
ShardSummary WriteFourViewShard(const fs::path& path, const std::string& metadata, uint32_t u) {
  ShardWriter w;
  ShardWriterOptions options;
  options.metadata_json = metadata;
  THROW_CHECK(w.Open(path, options).ok());
  for (uint32_t i = 0; i < 4; ++i) {
    const uint32_t id = u * 4 + i;
    THROW_CHECK(w.AddView(testing::SyntheticLabel(id), testing::SyntheticPoints(id, 9)).ok());
  }
  auto summary = w.Finish();
  THROW_CHECK(summary.ok());
  return *summary;
}

fs::path MakeDatabase(const std::string& name) {
  auto dir = TempDir(name);
  Manifest m;
  m.tool_version = "test";
  m.rolls = 48;
  for (uint32_t u = 0; u < 3; ++u) {
    char file[32];
    std::snprintf(file, sizeof(file), "shard-%05u.hdb", u);
    m.AddShard(WriteFourViewShard(dir / file, testing::SyntheticMetadata(), u));
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

// A database whose shards record what the converter records (rolls, tool version, unit,
// generation, hand model, conversion, labels, shapes, skipped renders) and whose manifest agrees.
fs::path MakeRecordedDatabase(const std::string& name) {
  auto dir = TempDir(name);
  const nlohmann::json hand = nlohmann::json::parse(testing::SyntheticMetadata())["hand_model"];
  const nlohmann::json generation = {{"seed", 7}, {"rolls", 48}, {"config", {{"k", 2}}}};
  const nlohmann::json conversion = {
      {"edges", {{"min_depth_jump", 3.5}, {"joint_pairs", {{1, 2}}}}},
      {"normalisation", {{"diameter_px", 192}}}};
  const nlohmann::json labels = {{"joint_angles", {{"unit", "rad"}}}};
  const nlohmann::json shapes = {{{"id", 0}, {"name", "fist"}}, {{"id", 1}, {"name", "flat"}}};
  const ManifestSkipped skipped{99, "units/u00001/r000099.exr", "no hand pixels"};
  Manifest m;
  m.tool_version = "test";
  m.rolls = 48;
  m.metadata = {{"generation", generation},
                {"hand_model", hand},
                {"conversion", conversion},
                {"labels", labels},
                {"shapes", shapes}};
  m.skipped = {skipped};
  for (uint32_t u = 0; u < 3; ++u) {
    char file[32];
    std::snprintf(file, sizeof(file), "shard-%05u.hdb", u);
    nlohmann::json skipped_here = nlohmann::json::array();
    if (u == 1) {
      skipped_here.push_back(
          {{"render_id", skipped.render_id}, {"file", skipped.file}, {"reason", skipped.reason}});
    }
    const nlohmann::json meta = {{"unit", u},
                                 {"rolls", 48},
                                 {"tool", {{"name", "handdb"}, {"version", "test"}}},
                                 {"generation", generation},
                                 {"hand_model", hand},
                                 {"conversion", conversion},
                                 {"labels", labels},
                                 {"shapes", shapes},
                                 {"skipped", skipped_here}};
    m.AddShard(WriteFourViewShard(dir / file, meta.dump(), u));
  }
  THROW_CHECK(WriteManifest(dir, m).ok());
  return dir;
}

// Validates the recorded database after `edit` changed its manifest.
template <typename F>
ValidationReport ValidateWithManifest(const std::string& name, F edit) {
  auto dir = MakeRecordedDatabase(name);
  auto m = ReadManifest(dir);
  THROW_CHECK(m.ok());
  edit(dir, &*m);
  m->UpdateTotals();
  THROW_CHECK(WriteManifest(dir, *m).ok());
  ValidationReport report = ValidatePath(dir);
  fs::remove_all(dir);
  return report;
}

// Manifest rolls 24 over shards made with 48 must not pass validate (query would search 24
// rolls). Every manifest field is compared with what the shards record.
TEST(Validator, ManifestFieldsAreCrossCheckedAgainstTheShards) {
  EXPECT_TRUE(ValidateWithManifest("xc_good", [](const fs::path&, Manifest*) {}).ok());

  auto report =
      ValidateWithManifest("xc_rolls", [](const fs::path&, Manifest* m) { m->rolls = 24; });
  EXPECT_EQ(report.problems.size(), 3u) << Dump(report);  // one per shard
  EXPECT_EQ(Count(report,
                  StatusCode::kSizeMismatch,
                  "shard-00000.hdb: rolls is 24 in the manifest but 48 in the shard's metadata "
                  "(rolls)"),
            1u)
      << Dump(report);

  report = ValidateWithManifest(
      "xc_generation", [](const fs::path&, Manifest* m) { m->metadata["generation"]["seed"] = 8; });
  EXPECT_EQ(report.problems.size(), 3u) << Dump(report);
  EXPECT_EQ(Count(report,
                  StatusCode::kSizeMismatch,
                  "metadata.generation.seed is 8 in the manifest but 7 in the shard's metadata "
                  "(generation.seed)"),
            3u)
      << Dump(report);

  report = ValidateWithManifest("xc_edges", [](const fs::path&, Manifest* m) {
    m->metadata["conversion"]["edges"]["joint_pairs"][0][1] = 3;
  });
  EXPECT_EQ(Count(report,
                  StatusCode::kSizeMismatch,
                  "metadata.conversion.edges.joint_pairs[0][1] is 3 in the manifest but 2"),
            3u)
      << Dump(report);

  for (const char* field : {"hand_model", "labels", "shapes"}) {
    SCOPED_TRACE(field);
    report = ValidateWithManifest(std::string("xc_") + field, [&](const fs::path&, Manifest* m) {
      m->metadata[field] = nlohmann::json::array();
    });
    EXPECT_EQ(
        Count(report, StatusCode::kSizeMismatch, "metadata." + std::string(field) + " is [] in"),
        3u)
        << Dump(report);
  }

  report = ValidateWithManifest("xc_tool",
                                [](const fs::path&, Manifest* m) { m->tool_version = "9.9"; });
  EXPECT_EQ(Count(report,
                  StatusCode::kSizeMismatch,
                  "tool_version is \"9.9\" in the manifest but \"test\" in the shard's metadata "
                  "(tool.version)"),
            3u)
      << Dump(report);

  // A shard listed under another unit's name.
  report = ValidateWithManifest("xc_unit", [](const fs::path& dir, Manifest* m) {
    fs::rename(dir / "shard-00002.hdb", dir / "shard-00007.hdb");
    m->shards[2].file = "shard-00007.hdb";
  });
  EXPECT_EQ(report.problems.size(), 1u) << Dump(report);
  EXPECT_EQ(Count(report,
                  StatusCode::kSizeMismatch,
                  "shard-00007.hdb: the manifest lists it as shard-00007.hdb but its metadata "
                  "records unit 2"),
            1u)
      << Dump(report);

  // Skipped renders: one the manifest invents, and one a shard records that the manifest drops.
  report = ValidateWithManifest("xc_skipped_extra", [](const fs::path&, Manifest* m) {
    m->skipped.push_back({5, "units/u00000/r000005.exr", "no hand pixels"});
  });
  EXPECT_EQ(report.problems.size(), 1u) << Dump(report);
  EXPECT_EQ(Count(report,
                  StatusCode::kSizeMismatch,
                  "manifest.json: skipped[] lists render 5 (units/u00000/r000005.exr: no hand "
                  "pixels), which no shard's metadata records"),
            1u)
      << Dump(report);
  report = ValidateWithManifest("xc_skipped_lost",
                                [](const fs::path&, Manifest* m) { m->skipped.clear(); });
  EXPECT_EQ(report.problems.size(), 1u) << Dump(report);
  EXPECT_EQ(Count(report,
                  StatusCode::kSizeMismatch,
                  "shard-00001.hdb: its metadata records skipped render 99 "
                  "(units/u00001/r000099.exr: no hand pixels), which the manifest's skipped[] "
                  "does not list"),
            1u)
      << Dump(report);

  // The label fields must describe the v1.0 view record.
  report = ValidateWithManifest("xc_labels",
                                [](const fs::path&, Manifest* m) { m->labels[3].count = 24; });
  EXPECT_EQ(report.problems.size(), 1u) << Dump(report);
  EXPECT_EQ(Count(report,
                  StatusCode::kSizeMismatch,
                  "manifest.json: labels[3] is {joint_angles, unit 'rad', count 24}, the v1.0 "
                  "view record has {joint_angles, unit 'rad', count 20}"),
            1u)
      << Dump(report);
}

// A field the manifest does not record: the shards must still agree with each other.
TEST(Validator, ShardsAgreeWithEachOtherWhereTheManifestIsSilent) {
  auto dir = MakeRecordedDatabase("xc_silent");
  auto m = ReadManifest(dir);
  ASSERT_TRUE(m.ok());
  m->metadata.erase("generation");
  ASSERT_TRUE(WriteManifest(dir, *m).ok());
  EXPECT_TRUE(ValidatePath(dir).ok()) << Dump(ValidatePath(dir));
  // Shard 2 rewritten with another seed (its manifest entry updated so only the seed differs).
  auto reader = ShardReader::Open(dir / "shard-00002.hdb");
  ASSERT_TRUE(reader.ok());
  nlohmann::json meta = nlohmann::json::parse(reader->metadata_json());
  meta["generation"]["seed"] = 8;
  ShardWriter w;
  ASSERT_TRUE(w.Open(dir / "shard-00002.tmp", {meta.dump(), {}}).ok());
  for (size_t i = 0; i < reader->num_views(); ++i) {
    const auto pts = reader->points(i);
    ASSERT_TRUE(w.AddView(reader->label(i), {pts.begin(), pts.end()}).ok());
  }
  auto summary = w.Finish();
  ASSERT_TRUE(summary.ok());
  fs::rename(dir / "shard-00002.tmp", dir / "shard-00002.hdb");
  m->shards.pop_back();
  m->AddShard(*summary);
  m->shards.back().file = "shard-00002.hdb";
  ASSERT_TRUE(WriteManifest(dir, *m).ok());
  auto report = ValidatePath(dir);
  EXPECT_EQ(report.problems.size(), 1u) << Dump(report);
  EXPECT_EQ(Count(report,
                  StatusCode::kSizeMismatch,
                  "shard-00002.hdb: generation.seed is 8 in the shard's metadata but 7 in "
                  "shard-00000.hdb (the manifest does not record metadata.generation)"),
            1u)
      << Dump(report);
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
