#include "generator/hand/database_rig.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include "base/atomic_file.h"
#include "base/sha256.h"
#include "base/testing.h"
#include "format/manifest.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

fs::path HandPath() { return RepoRoot() / "configs/hands/webxr_generic_right.json"; }

// A database directory reduced to what LoadDatabaseRig reads: a manifest (no shards) recording
// the hand model's sha256, the render settings and the generation config.
class DatabaseRigTest : public ::testing::Test {
 protected:
  void SetUp() override {
    db_ = fs::temp_directory_path() /
          ("handdb_database_rig_" + std::to_string(::getpid()) + "_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(db_);
    fs::create_directories(db_);
    auto sha = Sha256File(HandPath());
    ASSERT_TRUE(sha.ok());
    sha_ = *sha;
  }
  void TearDown() override { fs::remove_all(db_); }

  void WriteTheManifest(const std::string& sha, const json& config) {
    Manifest m;
    m.tool_version = "test";
    m.metadata = {{"hand_model", {{"name", "webxr-generic-right"}, {"sha256", sha}}},
                  {"generation", {{"resolution", 128}, {"ortho_scale", 0.3}, {"config", config}}}};
    m.UpdateTotals();
    ASSERT_TRUE(WriteManifest(db_, m).ok());
  }
  void WriteCopy(const std::string& extra = "") {
    auto text = ReadFileToString(HandPath());
    ASSERT_TRUE(text.ok());
    ASSERT_TRUE(WriteFileAtomic(db_ / kDatabaseHandModelFileName, *text + extra).ok());
  }

  fs::path db_;
  std::string sha_;
};

TEST_F(DatabaseRigTest, ReadsTheCopy) {
  WriteTheManifest(sha_, json::object());
  WriteCopy();
  auto rig = LoadDatabaseRig(db_);
  ASSERT_TRUE(rig.ok()) << rig.status().message();
  EXPECT_TRUE(rig->from_database_copy);
  EXPECT_EQ(rig->hand_model_file, db_ / kDatabaseHandModelFileName);
  EXPECT_EQ(rig->render.resolution, 128);
  EXPECT_EQ(rig->render.ortho_scale, 0.3);
  EXPECT_EQ(rig->rig.model().sha256, sha_);
}

TEST_F(DatabaseRigTest, RefusesACopyThatDisagreesWithTheRecord) {
  WriteTheManifest(sha_, json::object());
  WriteCopy(" ");
  auto rig = LoadDatabaseRig(db_);
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.status().code(), StatusCode::kChecksumMismatch);
  const std::string& m = rig.status().message();
  EXPECT_EQ(m.rfind((db_ / kDatabaseHandModelFileName).string() + ": sha256 ", 0), 0u) << m;
  EXPECT_NE(m.find(sha_), std::string::npos) << m;
  EXPECT_EQ(m.find('\n'), std::string::npos) << m;
}

TEST_F(DatabaseRigTest, WithoutACopyFallsBackToTheConfigsHandModel) {
  WriteTheManifest(sha_, json{{"hand_model", "configs/hands/webxr_generic_right.json"}});
  auto rig = LoadDatabaseRig(db_);
  ASSERT_TRUE(rig.ok()) << rig.status().message();
  EXPECT_FALSE(rig->from_database_copy);
  EXPECT_EQ(fs::weakly_canonical(rig->hand_model_file), fs::weakly_canonical(HandPath()));
}

TEST_F(DatabaseRigTest, WithoutACopyFallsBackToThePlanThatGenerateLeaves) {
  WriteTheManifest(sha_, json::object());  // a config that names no hand model
  EXPECT_EQ(LoadDatabaseRig(db_).status().code(), StatusCode::kNotFound);
  fs::create_directories(db_ / "render");
  ASSERT_TRUE(WriteFileAtomic(db_ / "render" / "plan.json",
                              json{{"hand_model", {{"path", HandPath().string()}}}}.dump())
                  .ok());
  auto rig = LoadDatabaseRig(db_);
  ASSERT_TRUE(rig.ok()) << rig.status().message();
  EXPECT_FALSE(rig->from_database_copy);
  EXPECT_EQ(rig->hand_model_file, HandPath());
}

TEST_F(DatabaseRigTest, WithoutACopyOrAMatchingFileIsAClearError) {
  const std::string other(64, 'a');
  WriteTheManifest(other, json{{"hand_model", "configs/hands/webxr_generic_right.json"}});
  auto rig = LoadDatabaseRig(db_);
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.status().code(), StatusCode::kNotFound);
  const std::string& m = rig.status().message();
  EXPECT_NE(m.find((db_ / kDatabaseHandModelFileName).string()), std::string::npos) << m;
  EXPECT_NE(m.find(other), std::string::npos) << m;
  EXPECT_NE(m.find("webxr_generic_right.json (sha256 " + sha_ + ")"), std::string::npos) << m;
}

TEST_F(DatabaseRigTest, NoManifestIsNotFound) {
  EXPECT_EQ(LoadDatabaseRig(db_).status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace handdb
