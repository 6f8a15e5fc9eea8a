// The driver with the real Blender and blender_scripts/render.py on a tiny plan (label `blender`):
// the contract between the two sides (entry-point arguments, file names, DONE marker, sidecars).
#include <gtest/gtest.h>
#include <unistd.h>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "generator/plan/plan.h"
#include "generator/render/render_driver.h"

namespace handdb {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

TEST(RenderDriverBlender, RendersATinyPlan) {
  if (!FindBlender("").ok()) GTEST_SKIP() << "Blender not installed";
  const fs::path dir =
      fs::temp_directory_path() / ("handdb_render_blender_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const json config =
      json::parse(R"({"seed": 0, "shapes": {"method": "basic", "names": ["flat", "fist"]},
      "views": {"method": "fibonacci", "count": 2}, "rolls": 4, "unit_size": 3,
      "render": {"resolution": 64}})");
  auto plan = MakePlan(config, dir / "config.json");
  ASSERT_TRUE(plan.ok()) << plan.status().message();
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "plan.json", *plan).ok());  // 4 renders: units of 3 and 1
  RenderOptions options;
  options.jobs = 2;
  options.progress = false;
  options.handle_signals = false;
  auto r = RenderPlan(dir / "plan.json", dir / "run", options);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->units_rendered, 2u);
  EXPECT_EQ(r->renders_done, 4u);
  for (uint32_t id = 0; id < 4; ++id) {
    const fs::path stem = dir / "run/units" / UnitDirName(id / 3) / RenderFileStem(id);
    EXPECT_GT(fs::file_size(stem.string() + ".exr"), 100u) << stem;
    auto sidecar = ReadJsonFile(stem.string() + ".json", "render_sidecar.schema.json");
    ASSERT_TRUE(sidecar.ok()) << sidecar.status().message();
    EXPECT_EQ((*sidecar)["render_id"].get<uint32_t>(), id);
    EXPECT_EQ((*sidecar)["shape_id"].get<uint32_t>(), id / 2);
    EXPECT_EQ((*sidecar)["dir_id"].get<uint32_t>(), id % 2);
  }
  // Resumable: a second run renders nothing.
  auto again = RenderPlan(dir / "run/plan.json", dir / "run", options);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->units_skipped, 2u);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace handdb
