#include "generator/pipeline.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "base/json_schema.h"
#include "base/repo_root.h"
#include "base/testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

GenerateOptions DemoOptions(const fs::path& dir) {
  GenerateOptions o;
  o.config_path = RepoRoot() / "configs/demo.json";
  o.db_dir = dir / "db";
  o.progress = false;
  return o;
}

TEST(GenerateOptions, Check) {
  const fs::path dir = testing::TempDir("pipeline_check");
  std::string error;
  EXPECT_TRUE(DemoOptions(dir).Check(&error)) << error;
  GenerateOptions no_db = DemoOptions(dir);
  no_db.db_dir.clear();
  EXPECT_FALSE(no_db.Check(&error));
  EXPECT_EQ(error, "no database directory");
  GenerateOptions bad_render = DemoOptions(dir);
  bad_render.render.jobs = 0;
  EXPECT_FALSE(bad_render.Check(&error));
}

TEST(GeneratePipeline, PlansIntoTheWorkDirectoryAndCountsTheIndexStage) {
  const fs::path dir = testing::TempDir("pipeline_plan");
  GenerateOptions o = DemoOptions(dir);
  std::vector<std::string> stages;
  o.on_stage = [&](int k, int n, const char* name) {
    stages.push_back(std::to_string(k) + "/" + std::to_string(n) + " " + name);
  };
  o.index_step = [](const fs::path&) { return Status::Ok(); };
  {
    GeneratePipeline pipeline(o);
    EXPECT_EQ(pipeline.work_dir(), dir / "db/render");
    ASSERT_TRUE(pipeline.Plan().ok());
    EXPECT_TRUE(fs::exists(dir / "db/render/plan.json"));
  }
  EXPECT_EQ(stages, (std::vector<std::string>{"1/5 plan"}));
  // Again (a resumed run): the same plan is accepted.
  GeneratePipeline again(o);
  EXPECT_TRUE(again.Plan().ok());
}

TEST(GeneratePipeline, RefusesAnotherConfigsPlanAndABadConfigLeavesNoDirectory) {
  const fs::path dir = testing::TempDir("pipeline_refuse");
  {
    GeneratePipeline pipeline(DemoOptions(dir));
    ASSERT_TRUE(pipeline.Plan().ok());
  }
  GenerateOptions other = DemoOptions(dir);
  other.config_path = RepoRoot() / "configs/paper.json";
  const Status s = GeneratePipeline(other).Plan();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("holds a different plan than"), std::string::npos) << s.message();

  GenerateOptions missing = DemoOptions(dir / "fresh");
  missing.config_path = dir / "no-such-config.json";
  EXPECT_FALSE(GeneratePipeline(missing).Plan().ok());
  EXPECT_FALSE(fs::exists(dir / "fresh"));
}

}  // namespace
}  // namespace handdb
