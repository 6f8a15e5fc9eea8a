#include "format/manifest.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <tuple>
#include <vector>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/testing.h"

namespace handdb {
namespace {

using testing::TempDir;

namespace fs = std::filesystem;

Manifest Sample() {
  Manifest m;
  m.tool_version = "0.1.0";
  m.rolls = 48;
  m.AddShard({"/somewhere/shard-00000.hdb", 10, 6000, 30016, "0123456789abcdef"});
  m.AddShard({"shard-00001.hdb", 7, 4200, 21056, "fedcba9876543210"});
  m.metadata = {{"config", {{"seed", 7}}}, {"hand_model_sha256", std::string(64, 'a')}};
  m.skipped.push_back({17, "units/u00001/r000017.exr", "no hand pixels"});
  return m;
}

TEST(Manifest, RoundTrip) {
  auto dir = TempDir("roundtrip");
  Manifest m = Sample();
  EXPECT_EQ(m.num_views, 17u);
  EXPECT_EQ(m.num_virtual_views, 17u * 48);
  EXPECT_EQ(m.shards[0].file, "shard-00000.hdb");  // file name only
  ASSERT_TRUE(WriteManifest(dir, m).ok());
  auto back = ReadManifest(dir);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(ManifestToJson(*back), ManifestToJson(m));
  EXPECT_EQ(back->skipped[0].reason, "no hand pixels");
  EXPECT_EQ(back->labels.size(), Manifest::ShardLabelFields().size());
  EXPECT_EQ(back->labels[3].name, "joint_angles");
  EXPECT_EQ(back->labels[3].unit, "rad");
  EXPECT_EQ(back->labels[3].count, 20u);
  // Stable bytes: writing what was read gives the same file.
  auto first = ReadFileToString(dir / "manifest.json");
  ASSERT_TRUE(WriteManifest(dir, *back).ok());
  EXPECT_EQ(*ReadFileToString(dir / "manifest.json"), *first);
  fs::remove_all(dir);
}

// What a reader returns comes from one manifest. A read during which the
// manifest is replaced (as a convert's swap does, by rename) runs again; a read during which it
// stays runs once; a manifest replaced on every attempt gives up after kManifestReadAttempts.
TEST(Manifest, ReadWithStableManifestRunsAgainAfterASwap) {
  auto dir = TempDir("stable");
  Manifest m = Sample();
  ASSERT_TRUE(WriteManifest(dir, m).ok());
  int calls = 0;
  auto rolls = ReadWithStableManifest(dir, [&]() -> Result<uint32_t> {
    auto read = ReadManifest(dir);
    if (!read.ok()) return read.status();
    if (++calls == 1) {  // the swap lands while this read runs
      Manifest next = m;
      next.rolls = 24;
      next.UpdateTotals();
      EXPECT_TRUE(WriteManifest(dir, next).ok());
    }
    return read->rolls;
  });
  EXPECT_EQ(calls, 2);
  ASSERT_TRUE(rolls.ok());
  EXPECT_EQ(*rolls, 24u);  // the second read's manifest, not the first's

  calls = 0;
  EXPECT_EQ(ReadWithStableManifest(dir, [&] { return ++calls; }), 1);
  // No manifest at all is stable too (the read reports kNotFound itself).
  fs::remove(dir / "manifest.json");
  EXPECT_EQ(StampManifest(dir), ManifestStamp{});
  EXPECT_EQ(ReadWithStableManifest(dir, [&] { return ++calls; }), 2);

  calls = 0;
  ReadWithStableManifest(dir, [&] {
    EXPECT_TRUE(WriteManifest(dir, m).ok());  // replaced on every attempt
    return ++calls;
  });
  EXPECT_EQ(calls, kManifestReadAttempts);
  fs::remove_all(dir);
}

TEST(Manifest, StagingFileNames) {
  EXPECT_TRUE(IsShardStagingFileName("shard-00007.next.hdb"));
  EXPECT_FALSE(IsShardStagingFileName("shard-00007.hdb"));
  EXPECT_FALSE(IsShardStagingFileName("shard-00007.next.hdb.tmp-x"));
  EXPECT_EQ(ShardFinalFileName("shard-00007.next.hdb"), "shard-00007.hdb");
  EXPECT_EQ(ShardFinalFileName("shard-00007.hdb"), "shard-00007.hdb");
  // The schema accepts a staging name in shards[] (the intermediate manifest of a rewrite).
  Manifest m = Sample();
  m.shards[1].file = "shard-00001.next.hdb";
  EXPECT_TRUE(ValidateJson(ManifestToJson(m), "manifest.schema.json", "m").ok());
  m.shards[1].file = "shard-00001.old.hdb";
  EXPECT_FALSE(ValidateJson(ManifestToJson(m), "manifest.schema.json", "m").ok());
}

TEST(Manifest, SchemaAcceptsWhatWeWrite) {
  EXPECT_FALSE(EmbeddedSchema("manifest.schema.json").empty());
  EXPECT_TRUE(ValidateJson(ManifestToJson(Sample()), "manifest.schema.json", "m").ok());
}

TEST(Manifest, RefusesToWriteInconsistentTotals) {
  auto dir = TempDir("totals");
  Manifest m = Sample();
  m.num_views = 99;
  Status s = WriteManifest(dir, m);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(fs::exists(dir / "manifest.json"));
  m = Sample();
  m.shards.push_back(m.shards[0]);
  m.UpdateTotals();
  EXPECT_EQ(WriteManifest(dir, m).code(), StatusCode::kInvalidArgument);
  m = Sample();
  m.shards[0].xxh3 = "XYZ";
  EXPECT_EQ(WriteManifest(dir, m).code(), StatusCode::kInvalidArgument);
  fs::remove_all(dir);
}

// rolls = 10^8 with a matching virtual-view count would pass validate and make `query` grow to
// 4 GB. The roll count is bounded (kMaxRolls) when a manifest is read or written.
TEST(Manifest, RefusesMoreRollsThanTheLimit) {
  auto dir = TempDir("rolls");
  Manifest m = Sample();
  m.rolls = kMaxRolls;
  m.UpdateTotals();
  ASSERT_TRUE(WriteManifest(dir, m).ok());
  ASSERT_TRUE(ReadManifest(dir).ok());
  m.rolls = 100000000;
  m.UpdateTotals();
  EXPECT_EQ(WriteManifest(dir, m).code(), StatusCode::kOutOfRange);
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "manifest.json", ManifestToJson(m)).ok());
  auto read = ReadManifest(dir);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kOutOfRange);
  EXPECT_EQ(read.status().message(),
            (dir / "manifest.json").string() +
                ": rolls is 100000000, more than the 3600 a database may have");
  fs::remove_all(dir);
}

TEST(Manifest, ReadErrors) {
  auto dir = TempDir("errors");
  auto missing = ReadManifest(dir);
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  ASSERT_TRUE(WriteFileAtomic(dir / "manifest.json", "{\"format\": ").ok());
  EXPECT_EQ(ReadManifest(dir).status().code(), StatusCode::kBadJson);
  auto doc = ManifestToJson(Sample());
  doc["shards"][1]["file"] = "../etc/passwd";
  ASSERT_TRUE(WriteFileAtomic(dir / "manifest.json", doc.dump()).ok());
  auto bad_name = ReadManifest(dir);
  EXPECT_EQ(bad_name.status().code(), StatusCode::kSchemaViolation);
  EXPECT_NE(bad_name.status().message().find("manifest.json"), std::string::npos);
  doc = ManifestToJson(Sample());
  doc["num_virtual_views"] = 5;
  ASSERT_TRUE(WriteFileAtomic(dir / "manifest.json", doc.dump()).ok());
  EXPECT_EQ(ReadManifest(dir).status().code(), StatusCode::kSizeMismatch);
  doc = ManifestToJson(Sample());
  doc["format"] = "something-else";
  ASSERT_TRUE(WriteFileAtomic(dir / "manifest.json", doc.dump()).ok());
  EXPECT_EQ(ReadManifest(dir).status().code(), StatusCode::kSchemaViolation);
  fs::remove_all(dir);
}

// rolls 2^32 + 12 was read as 12 and a label count of 2^32 + 1 as 1.
TEST(Manifest, IntegersBeyondTheirFieldsTypeAreRefused) {
  auto dir = TempDir("integers");
  for (const auto& [pointer, value, message] :
       std::vector<std::tuple<std::string, nlohmann::json, std::string>>{
           {"/rolls", 4294967308ull, "rolls is 4294967308, not an integer in 0..4294967295"},
           {"/labels/0/count",
            4294967297ull,
            "labels[0].count is 4294967297, not an integer in 0..4294967295"},
           {"/num_views",
            nlohmann::json::parse("18446744073709551628"),
            "num_views is 1.8446744073709552e+19, not an integer in 0..18446744073709551615"}}) {
    SCOPED_TRACE(pointer);
    auto doc = ManifestToJson(Sample());
    doc[nlohmann::json::json_pointer(pointer)] = value;
    ASSERT_TRUE(WriteFileAtomic(dir / "manifest.json", doc.dump()).ok());
    auto r = ReadManifest(dir);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kOutOfRange);
    EXPECT_EQ(r.status().message(), (dir / "manifest.json").string() + ": " + message);
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace handdb
