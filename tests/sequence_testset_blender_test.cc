// Test sequences end to end with the real Blender (CTest labels `blender`, `integration`):
// `handdb testset` renders tests/data/testset-sequence-tiny.json (two sequences of 8 frames at
// 128 px, the second leaving the picture and coming back), its truth marks the frames out of the
// picture, the per-sequence frame folders link to the photos, a rerun renders nothing; then
// `handdb evaluate` scores the sequences against a tiny database (one shape, 12 directions, 4
// rolls) with the tracker and with the each-frame-alone baseline, and writes reports that match
// their schema.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/repo_root.h"
#include "base/testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

using handdb::testing::CliRun;

// `handdb ARGS`, stdout and stderr captured.
CliRun Handdb(const std::string& args) {
  return handdb::testing::RunShell(std::string(HANDDB_BINARY) + " " + args);
}

bool HaveBlender() { return std::system("command -v blender >/dev/null 2>&1") == 0; }

TEST(SequenceTestSetBlender, RendersTruthFoldersAndScores) {
  if (!HaveBlender()) GTEST_SKIP() << "blender not on PATH";
  const fs::path dir = fs::temp_directory_path() / ("handdb-seq-e2e-" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path root = RepoRoot();
  const fs::path ts = dir / "ts";
  const std::string render = "testset " +
                             (root / "tests/data/testset-sequence-tiny.json").string() + " --out " +
                             ts.string() + " -j 2 -q --json";
  CliRun r = Handdb(render);
  ASSERT_EQ(r.code, 0) << r.err;

  auto truth = ReadJsonFile(ts / "testset.json", "testset.schema.json");
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  ASSERT_EQ(truth->at("items").size(), 16u);
  EXPECT_EQ(truth->at("sequence").at("frames"), 8);
  for (const json& item : truth->at("items")) {
    const json& s = item.at("sequence");
    const int sequence = s.at("id");
    const int frame = s.at("frame");
    EXPECT_EQ(s.at("clutter").get<bool>(), sequence == 1);
    // Sequence 1 leaves from frame 2 (0.25 x 8): frames 3 and 5 on the way, 4 wholly out.
    const bool out = sequence == 1 && frame >= 3 && frame <= 5;
    EXPECT_EQ(s.at("visible").get<bool>(), !out) << sequence << "/" << frame;
    if (sequence == 1 && frame == 4) {
      EXPECT_EQ(s.at("in_picture"), 0);
    }
    // The frame folder's file is the frame's photo.
    const fs::path link = ts / s.at("frame_file").get<std::string>();
    ASSERT_TRUE(fs::is_symlink(link)) << link;
    EXPECT_TRUE(fs::equivalent(link, ts / item.at("photo").get<std::string>())) << link;
  }

  // A rerun of the same command renders nothing.
  r = Handdb(render);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out).at("units_rendered"), 0) << r.out;

  const json db_config = {
      {"name", "seq-e2e"},
      {"seed", 5},
      {"hand_model", (root / "configs/hands/webxr_generic_right.json").string()},
      {"shapes",
       {{"method", "basic"},
        {"library", (root / "configs/shapes/basic.json").string()},
        {"names", {"fist"}}}},
      {"views", {{"method", "icosahedron"}, {"count", 12}}},
      {"rolls", 4},
      {"unit_size", 12},
      {"render", {{"resolution", 64}}}};
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "db.json", db_config).ok());
  r = Handdb("generate " + (dir / "db.json").string() + " -o " + (dir / "db").string() +
             " -j 2 -q");
  ASSERT_EQ(r.code, 0) << r.err;

  const fs::path report_path = dir / "seq.json";
  r = Handdb("evaluate " + (dir / "db").string() + " " + ts.string() + " --json " +
             report_path.string() + " --threads 2 --fit off");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("overall"), std::string::npos) << r.out;
  auto report = ReadJsonFile(report_path, "sequence_evaluation.schema.json");
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_EQ(report->at("sequences").size(), 2u);
  const json& overall = report->at("overall");
  EXPECT_EQ(overall.at("frames"), 16);
  EXPECT_EQ(overall.at("visible_frames"), 13);
  EXPECT_EQ(overall.at("recovery").at("returns"), 1);
  EXPECT_GT(overall.at("frames_per_second").get<double>(), 0);
  // The frames where the hand is wholly in the picture are found from the photo alone.
  EXPECT_GE(overall.at("found_visible").get<int>(), 10);

  // The baseline: each frame answered alone.
  r = Handdb("evaluate " + (dir / "db").string() + " " + ts.string() + " --json " +
             report_path.string() + " --threads 2 --fit off --predictor alone");
  ASSERT_EQ(r.code, 0) << r.err;
  auto alone = ReadJsonFile(report_path, "sequence_evaluation.schema.json");
  ASSERT_TRUE(alone.ok()) << alone.status().ToString();
  EXPECT_EQ(alone->at("overall").at("frames"), 16);
  EXPECT_GE(alone->at("overall").at("found_visible").get<int>(), 10);
  EXPECT_NE(alone->at("predictor").get<std::string>().find("alone"), std::string::npos);
  EXPECT_NE(report->at("predictor").get<std::string>().find("tracker"), std::string::npos);

  // A sequence is scored from its photos.
  r = Handdb("evaluate " + (dir / "db").string() + " " + ts.string() + " --input clean");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("sequence test set"), std::string::npos) << r.err;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace handdb
