// `handdb index` end to end: the index file listed in the manifest, deterministic
// builds, `handdb validate` checking it, `handdb query` searching indexed by default (and exact
// on request) with the JSON saying which ran, and one-line errors for a damaged index.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>

#include "base/testing.h"
#include "format/manifest.h"
#include "format/roll.h"
#include "format/shard_writer.h"
#include "query/search_testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

using handdb::testing::CliRun;

// `handdb ARGS`, stdout and stderr captured.
CliRun Handdb(const std::string& args) {
  return handdb::testing::RunShell(std::string(HANDDB_BINARY) + " " + args);
}

constexpr uint32_t kViews = 80;
constexpr uint32_t kRolls = 12;

class IndexCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("handdb-icli-db-" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "db");
    Manifest manifest;
    manifest.tool_version = "index_cli_test";
    manifest.rolls = kRolls;
    ShardWriter w;
    ASSERT_TRUE(w.Open(dir_ / "db" / "shard-00000.hdb", ShardWriterOptions{}).ok());
    for (uint32_t v = 0; v < kViews; ++v) {
      ASSERT_TRUE(
          w.AddView(testing::SyntheticViewLabel(v, 10), testing::SyntheticEdgeSet(v, 300)).ok());
    }
    auto summary = w.Finish();
    ASSERT_TRUE(summary.ok());
    manifest.AddShard(*summary);
    ASSERT_TRUE(WriteManifest(dir_ / "db", manifest).ok());
    // An edge image of view 37 at roll 5.
    std::vector<Point2f> rolled;
    RollPoints(testing::SyntheticEdgeSet(37, 300), RollAngle(5, kRolls), &rolled);
    cv::Mat edges = cv::Mat::zeros(400, 400, CV_8U);
    for (const auto& p : rolled) {
      edges.at<uint8_t>(static_cast<int>(std::lround(200 + 1.5 * p.y)),
                        static_cast<int>(std::lround(200 + 1.5 * p.x))) = 255;
    }
    ASSERT_TRUE(cv::imwrite((dir_ / "q.png").string(), edges));
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string db() const { return (dir_ / "db").string(); }
  std::string image() const { return (dir_ / "q.png").string(); }
  nlohmann::json ManifestJson() const {
    std::ifstream f(dir_ / "db" / "manifest.json");
    return nlohmann::json::parse(f);
  }
  fs::path dir_;
};

TEST_F(IndexCli, BuildsAValidatedIndexThatQuerySearchesByDefault) {
  const CliRun before = Handdb("query " + db() + " " + image() + " --json --top 3 -q");
  ASSERT_EQ(before.code, 0) << before.err;
  EXPECT_EQ(nlohmann::json::parse(before.out)["options"]["search"], "exact");
  const CliRun forced = Handdb("query " + db() + " " + image() + " --search indexed -q");
  EXPECT_EQ(forced.code, 1);
  EXPECT_NE(forced.err.find("handdb index"), std::string::npos) << forced.err;

  const CliRun built =
      Handdb("index " + db() + " --dims 16 --nlist 8 --cell-px 16 --grid-side 15 -j 2");
  ASSERT_EQ(built.code, 0) << built.err;
  EXPECT_NE(built.out.find("80 views x 12 rolls"), std::string::npos) << built.out;
  const nlohmann::json m = ManifestJson();
  ASSERT_TRUE(m.contains("index")) << m.dump();
  const std::string file = m["index"]["file"];
  EXPECT_TRUE(fs::exists(dir_ / "db" / file));
  EXPECT_EQ(m["index"]["bytes"], fs::file_size(dir_ / "db" / file));
  const CliRun valid = Handdb("validate " + db() + " -q");
  EXPECT_EQ(valid.code, 0) << valid.err;

  // The same options again: the same bytes, so the same name, and still one index file.
  ASSERT_EQ(Handdb("index " + db() + " --dims 16 --nlist 8 --cell-px 16 --grid-side 15 -q").code,
            0);
  EXPECT_EQ(ManifestJson()["index"]["file"], file);
  int index_files = 0;
  for (const auto& e : fs::directory_iterator(dir_ / "db")) {
    index_files += e.path().extension() == ".hdbi";
  }
  EXPECT_EQ(index_files, 1);

  // 100 candidates of the 960 pairs per hand, every list searched.
  const CliRun indexed =
      Handdb("query " + db() + " " + image() + " --json --top 3 --candidates 100 --nprobe 8 -q");
  ASSERT_EQ(indexed.code, 0) << indexed.err;
  const nlohmann::json ij = nlohmann::json::parse(indexed.out);
  EXPECT_EQ(ij["options"]["search"], "indexed");
  EXPECT_EQ(ij["stats"]["candidates"].get<int>(), 200);  // both hands
  const CliRun exact =
      Handdb("query " + db() + " " + image() + " --json --top 3 --search exact -q");
  ASSERT_EQ(exact.code, 0) << exact.err;
  const nlohmann::json ej = nlohmann::json::parse(exact.out);
  EXPECT_EQ(ej["options"]["search"], "exact");
  EXPECT_EQ(ej["stats"]["candidates"], 0);
  EXPECT_EQ(ij["matches"][0]["view_id"], 37);
  EXPECT_EQ(ij["matches"][0]["roll"], 5);
  EXPECT_EQ(ij["matches"][0]["distance"], ej["matches"][0]["distance"]);
  const CliRun table = Handdb("query " + db() + " " + image() + " -q");
  EXPECT_NE(table.out.find("indexed search:"), std::string::npos) << table.out;
  const CliRun info = Handdb("info " + db());
  EXPECT_NE(info.out.find("index         " + file), std::string::npos) << info.out;
}

// Indexed search reads the shards' own coarse fields (row-major, in place) where exact search
// reads the Searcher's cell-major copy: with every pair a candidate, both give the same top k.
TEST_F(IndexCli, IndexedSearchOfEveryPairReadsTheShardsFieldsAndIsExact) {
  ASSERT_EQ(Handdb("index " + db() + " --dims 16 --nlist 8 --cell-px 16 --grid-side 15 -q").code,
            0);
  for (const std::string hand : {"right", "either"}) {
    const std::string common = " --json --top 10 -q --hand " + hand;
    const CliRun exact = Handdb("query " + db() + " " + image() + common + " --search exact");
    const CliRun indexed =
        Handdb("query " + db() + " " + image() + common + " --search indexed --candidates " +
               std::to_string(kViews * kRolls));
    ASSERT_EQ(exact.code, 0) << exact.err;
    ASSERT_EQ(indexed.code, 0) << indexed.err;
    const nlohmann::json e = nlohmann::json::parse(exact.out)["matches"];
    const nlohmann::json i = nlohmann::json::parse(indexed.out)["matches"];
    ASSERT_EQ(e.size(), 10u);
    ASSERT_EQ(i.size(), e.size());
    for (size_t k = 0; k < e.size(); ++k) {
      for (const char* field : {"view_id", "roll", "hand", "distance"}) {
        EXPECT_EQ(i[k][field], e[k][field]) << hand << " rank " << k << " " << field;
      }
    }
  }
}

TEST_F(IndexCli, ADamagedIndexIsOneLineNamingTheFile) {
  ASSERT_EQ(Handdb("index " + db() + " --dims 8 --nlist 4 --cell-px 16 --grid-side 15 -q").code, 0);
  const fs::path file = dir_ / "db" / ManifestJson()["index"]["file"].get<std::string>();
  {
    std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(fs::file_size(file) / 2));
    f.put('\x5a');
  }
  const CliRun valid = Handdb("validate " + db() + " -q");
  EXPECT_EQ(valid.code, 1);
  EXPECT_NE(valid.err.find(file.string()), std::string::npos) << valid.err;
  const CliRun query = Handdb("query " + db() + " " + image() + " -q");
  EXPECT_EQ(query.code, 1);
  EXPECT_NE(query.err.find(file.string()), std::string::npos) << query.err;
  EXPECT_EQ(std::count(query.err.begin(), query.err.end(), '\n'), 1) << query.err;
  // Exact search does not read the index.
  EXPECT_EQ(Handdb("query " + db() + " " + image() + " --search exact -q").code, 0);
  fs::remove(file);
  const CliRun missing = Handdb("query " + db() + " " + image() + " -q");
  EXPECT_EQ(missing.code, 1);
  EXPECT_NE(missing.err.find(file.string()), std::string::npos) << missing.err;
}

TEST_F(IndexCli, BadOptionsAreUsageErrors) {
  EXPECT_EQ(Handdb("index " + db() + " --dims 0").code, 2);
  EXPECT_EQ(Handdb("index " + db() + " --dims 5000").code, 2);
  EXPECT_EQ(Handdb("index " + db() + " --grid-side 4").code, 2);
  const CliRun none = Handdb("index " + (dir_ / "nope").string());
  EXPECT_EQ(none.code, 1);
  EXPECT_NE(none.err.find("nope"), std::string::npos) << none.err;
  EXPECT_EQ(Handdb("query " + db() + " " + image() + " --search fast").code, 2);
  EXPECT_FALSE(ManifestJson().contains("index"));
}

}  // namespace
}  // namespace handdb
