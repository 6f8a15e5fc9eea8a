// The driver's process handling (parallel workers, resume, retries, failures, cancel) against a
// test double of the Blender executable: a small Python script that follows the documented entry
// point (docs/conventions.md "Blender entry point") and writes files the way render.py does. The
// real Blender path is covered by the `blender`-labelled integration tests.
#include "generator/render/render_driver.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <thread>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/testing.h"
#include "generator/plan/plan.h"

namespace handdb {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

// FAKE_BLENDER_MODE: ok | fail_first (each unit fails its first attempt) | fail_unit1 (unit 1
// always fails) | enospc_unit1 (unit 1 fails as Blender does on a full disk) | crash_first
// (SIGKILLs itself on the first attempt) | no_done | hang.
constexpr const char* kFakeBlender = R"PY(#!/usr/bin/python3
import json, os, signal, sys, time
args = sys.argv[sys.argv.index("--") + 1:]
opt = {args[i]: args[i + 1] for i in range(0, len(args) - 1, 2)}
plan, unit, out = opt["--plan"], int(opt["--unit"]), opt["--out"]
mode = os.environ.get("FAKE_BLENDER_MODE", "ok")
with open(os.path.join(out, "spawns.log"), "a") as f:
    f.write("%d\n" % unit)
marker = os.path.join(out, "attempted-%d" % unit)
first = not os.path.exists(marker)
open(marker, "w").close()
print("Blender 3.4.1 (fake)")
if mode == "hang":
    time.sleep(600)
if mode == "crash_first" and first:
    os.kill(os.getpid(), signal.SIGKILL)
if mode == "enospc_unit1" and unit == 1:
    print("Error: writing r000010.exr.tmp: No space left on device")
    print("handdb-render: r000010.exr.tmp: Blender wrote an unreadable EXR header", file=sys.stderr)
    sys.exit(1)
if (mode == "fail_first" and first) or (mode == "fail_unit1" and unit == 1):
    print("handdb-render: simulated failure in unit %d" % unit, file=sys.stderr)
    sys.exit(1)
doc = json.load(open(plan))
d = os.path.join(out, "units", "u%05d" % unit)
os.makedirs(d, exist_ok=True)
for r in doc["units"][unit]["renders"]:
    stem = os.path.join(d, "r%06d" % r["render_id"])
    open(stem + ".exr", "wb").write(b"fake")
    json.dump({"render_id": r["render_id"]}, open(stem + ".json", "w"))
    print("rendered", r["render_id"])
if mode != "no_done":
    open(os.path.join(d, "DONE"), "w").close()
)PY";

class RenderDriverTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = handdb::testing::TempDir(
        std::string("render_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_ / "scripts");
    ASSERT_TRUE(WriteFileAtomic(dir_ / "fake-blender", kFakeBlender).ok());
    ::chmod((dir_ / "fake-blender").c_str(), 0755);
    // The driver only checks that the script exists; the fake ignores it.
    ASSERT_TRUE(WriteFileAtomic(dir_ / "scripts" / "render.py", "# unused by the fake\n").ok());
    const json config = json::parse(R"({"seed": 0, "shapes": {"method": "basic", "count": 2},
        "views": {"method": "fibonacci", "count": 12}, "rolls": 4, "unit_size": 10})");
    auto plan = MakePlan(config, dir_ / "config.json");
    ASSERT_TRUE(plan.ok()) << plan.status().message();
    ASSERT_TRUE(
        WriteJsonFileAtomic(dir_ / "plan.json", *plan).ok());  // 24 renders: units of 10, 10, 4
    options_.blender = dir_ / "fake-blender";
    options_.scripts_dir = dir_ / "scripts";
    options_.jobs = 2;
    options_.progress = false;
    options_.handle_signals = false;
    ::setenv("FAKE_BLENDER_MODE", "ok", 1);
  }
  void TearDown() override {
    ::unsetenv("FAKE_BLENDER_MODE");
    fs::remove_all(dir_);
  }
  int Spawns() const {
    std::ifstream in(dir_ / "run" / "spawns.log");
    int n = 0;
    std::string line;
    while (std::getline(in, line)) ++n;
    return n;
  }
  fs::path dir_;
  RenderOptions options_;
};

TEST_F(RenderDriverTest, RendersEveryUnitAndResumes) {
  auto r = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->units_total, 3u);
  EXPECT_EQ(r->units_rendered, 3u);
  EXPECT_EQ(r->renders_total, 24u);
  EXPECT_EQ(r->renders_done, 24u);
  EXPECT_EQ(r->retries, 0u);
  for (int u = 0; u < 3; ++u) {
    EXPECT_TRUE(fs::exists(dir_ / "run/units" / UnitDirName(u) / "DONE"));
    EXPECT_TRUE(fs::exists(dir_ / "run/logs" / (UnitDirName(u) + ".log")));
  }
  EXPECT_TRUE(fs::exists(dir_ / "run/units/u00002/r000023.exr"));
  auto copy = ReadFileToString(dir_ / "run/plan.json");
  auto original = ReadFileToString(dir_ / "plan.json");
  ASSERT_TRUE(copy.ok() && original.ok());
  EXPECT_EQ(*copy, *original);
  EXPECT_EQ(Spawns(), 3);

  // A rerun starts nothing; so does a run on the copied plan.
  auto again = RenderPlan(dir_ / "run/plan.json", dir_ / "run", options_);
  ASSERT_TRUE(again.ok()) << again.status().message();
  EXPECT_EQ(again->units_skipped, 3u);
  EXPECT_EQ(again->units_rendered, 0u);
  EXPECT_EQ(Spawns(), 3);

  // Removing one DONE marker re-runs only that unit.
  fs::remove(dir_ / "run/units/u00001/DONE");
  auto one = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  ASSERT_TRUE(one.ok());
  EXPECT_EQ(one->units_rendered, 1u);
  EXPECT_EQ(Spawns(), 4);
}

TEST_F(RenderDriverTest, ReportsEachCompletedUnit) {
  std::vector<uint32_t> done;
  options_.on_unit_done = [&](uint32_t unit) {
    EXPECT_TRUE(fs::exists(dir_ / "run/units" / UnitDirName(unit) / "DONE"));
    done.push_back(unit);
  };
  ASSERT_TRUE(RenderPlan(dir_ / "plan.json", dir_ / "run", options_).ok());
  std::sort(done.begin(), done.end());
  EXPECT_EQ(done, (std::vector<uint32_t>{0, 1, 2}));
}

TEST_F(RenderDriverTest, SelectedUnitsOnly) {
  options_.units = {2};
  auto r = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->units_total, 1u);
  EXPECT_EQ(r->renders_done, 4u);
  EXPECT_FALSE(fs::exists(dir_ / "run/units/u00000"));
  options_.units = {3};
  auto bad = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
}

TEST_F(RenderDriverTest, RetriesAFailedOrCrashedWorker) {
  for (const char* mode : {"fail_first", "crash_first"}) {
    fs::remove_all(dir_ / "run");
    ::setenv("FAKE_BLENDER_MODE", mode, 1);
    auto r = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
    ASSERT_TRUE(r.ok()) << mode << ": " << r.status().message();
    EXPECT_EQ(r->retries, 3u) << mode;
    EXPECT_EQ(r->units_rendered, 3u) << mode;
    EXPECT_EQ(Spawns(), 6) << mode;
    std::ifstream log(dir_ / "run/logs/u00000.log");
    std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("attempt 2/3"), std::string::npos) << text;
  }
}

TEST_F(RenderDriverTest, GivesUpWithTheUnitAndItsLog) {
  ::setenv("FAKE_BLENDER_MODE", "fail_unit1", 1);
  options_.jobs = 1;
  auto r = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kExternalToolFailed);
  const std::string& m = r.status().message();
  EXPECT_NE(m.find("unit 1 failed after 3 attempts (exit code 1)"), std::string::npos) << m;
  EXPECT_NE(m.find("handdb-render: simulated failure in unit 1"), std::string::npos) << m;
  EXPECT_NE(m.find("logs/u00001.log"), std::string::npos) << m;
  EXPECT_EQ(m.find('\n'), std::string::npos);
  EXPECT_TRUE(fs::exists(dir_ / "run/units/u00000/DONE"));  // finished work stays

  ::setenv("FAKE_BLENDER_MODE", "no_done", 1);
  options_.max_retries = 0;
  fs::remove_all(dir_ / "run");
  r = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("no DONE marker"), std::string::npos) << r.status().message();
}

// A full disk shows in the worker's result as "unreadable EXR header", the real cause only in
// the log. The message says the disk is full, from the log's line or from the filesystem's free
// space.
TEST_F(RenderDriverTest, AFullDiskIsNamedAsTheCause) {
  ::setenv("FAKE_BLENDER_MODE", "enospc_unit1", 1);
  options_.jobs = 1;
  options_.max_retries = 0;
  auto r = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  ASSERT_FALSE(r.ok());
  const std::string& m = r.status().message();
  EXPECT_NE(m.find("unit 1 failed after 1 attempt (exit code 1): the disk is full (the log says: "
                   "Error: writing r000010.exr.tmp: No space left on device): handdb-render: "),
            std::string::npos)
      << m;
  EXPECT_EQ(m.find('\n'), std::string::npos);
  // A failure with plenty of space left says nothing about the disk.
  ::setenv("FAKE_BLENDER_MODE", "fail_unit1", 1);
  fs::remove_all(dir_ / "run");
  r = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message().find("disk is full"), std::string::npos) << r.status().message();

  // On a really full filesystem (a 256 KiB tmpfs; needs mount rights) without the log line.
  const fs::path full = dir_ / "full";
  fs::create_directories(full);
  if (std::system(
          ("mount -t tmpfs -o size=256k tmpfs " + full.string() + " 2>/dev/null").c_str()) != 0) {
    GTEST_SKIP() << "cannot mount a tmpfs here";
  }
  r = RenderPlan(dir_ / "plan.json", full / "run", options_);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("failed after 1 attempt (exit code 1): the disk is full (" +
                                      (full / "run").string() + ": "),
            std::string::npos)
      << r.status().message();
  std::system(("umount " + full.string()).c_str());
}

TEST_F(RenderDriverTest, CancelKillsWorkersQuickly) {
  ::setenv("FAKE_BLENDER_MODE", "hang", 1);
  std::atomic<bool> cancel{false};
  options_.cancel = &cancel;
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    cancel = true;
  });
  const auto start = std::chrono::steady_clock::now();
  auto r = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  stopper.join();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kCancelled);
  EXPECT_LT(seconds, 10.0);
}

// A hung Blender must not hold the run forever. A worker whose unit finishes no render
// for stall_timeout_seconds is killed and its unit retried; the last failure names the cause.
TEST_F(RenderDriverTest, HungWorkerIsKilledAfterTheStallTimeout) {
  ::setenv("FAKE_BLENDER_MODE", "hang", 1);
  options_.stall_timeout_seconds = 0.5;
  options_.max_retries = 1;
  const auto start = std::chrono::steady_clock::now();
  auto r = RenderPlan(dir_ / "plan.json", dir_ / "run", options_);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kExternalToolFailed);
  EXPECT_NE(r.status().message().find("failed after 2 attempts (no render finished in 0.5 s: "
                                      "killed as hung)"),
            std::string::npos)
      << r.status().message();
  EXPECT_LT(seconds, 20.0);  // the fake hangs for 600 s
}

TEST_F(RenderDriverTest, ChecksEverythingBeforeRendering) {
  // Missing Blender.
  RenderOptions o = options_;
  o.blender = dir_ / "no-such-blender";
  auto r = RenderPlan(dir_ / "plan.json", dir_ / "run", o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_NE(r.status().message().find("no-such-blender"), std::string::npos);

  // Missing render script.
  o = options_;
  o.scripts_dir = dir_ / "nowhere";
  r = RenderPlan(dir_ / "plan.json", dir_ / "run", o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("render.py"), std::string::npos);

  // An invalid plan.
  auto text = ReadFileToString(dir_ / "plan.json");
  ASSERT_TRUE(text.ok());
  json doc = json::parse(*text);
  json broken = doc;
  broken["units"][0]["renders"][0].erase("joints");
  ASSERT_TRUE(WriteJsonFileAtomic(dir_ / "broken.json", broken).ok());
  r = RenderPlan(dir_ / "broken.json", dir_ / "run", options_);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kSchemaViolation);

  // A plan whose hand model changed since.
  json stale = doc;
  stale["hand_model"]["sha256"] = std::string(64, '0');
  ASSERT_TRUE(WriteJsonFileAtomic(dir_ / "stale.json", stale).ok());
  r = RenderPlan(dir_ / "stale.json", dir_ / "run", options_);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kChecksumMismatch);

  EXPECT_FALSE(fs::exists(dir_ / "run" / "spawns.log"));  // nothing ran

  // A run directory that holds another plan.
  ASSERT_TRUE(RenderPlan(dir_ / "plan.json", dir_ / "run", options_).ok());
  r = RenderPlan(dir_ / "stale.json", dir_ / "run", options_);
  ASSERT_FALSE(r.ok());
}

TEST(RenderOptions, Check) {
  RenderOptions o;
  EXPECT_TRUE(o.Check());
  o.jobs = 0;
  EXPECT_FALSE(o.Check());
  o.jobs = 2;
  o.max_retries = -1;
  EXPECT_FALSE(o.Check());
  o.max_retries = 0;
  o.stall_timeout_seconds = -1;
  EXPECT_FALSE(o.Check());
}

TEST(FindBlender, ExplicitPathMustBeExecutable) {
  auto r = FindBlender("/definitely/not/blender");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  auto sh = FindBlender("/bin/sh");
  ASSERT_TRUE(sh.ok());
}

}  // namespace
}  // namespace handdb
