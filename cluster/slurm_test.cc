#include "cluster/slurm.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "base/atomic_file.h"
#include "cluster/slurm_testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

TEST(Slurm, FormatArrayRanges) {
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{}), "");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{5}), "5");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{0, 1, 2, 3}), "0-3");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{0, 1, 2, 3, 7, 9, 10, 11, 12}), "0-3,7,9-12");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{1, 3, 5}), "1,3,5");
  EXPECT_EQ(FormatArrayRanges(std::vector<uint32_t>{4, 5}), "4-5");
}

TEST(Slurm, ArraySpecAddsThrottle) {
  ArrayChunk chunk{0, {0, 1, 2, 6}};
  EXPECT_EQ(chunk.ArraySpec(0), "0-2,6");
  EXPECT_EQ(chunk.ArraySpec(4), "0-2,6%4");
}

TEST(Slurm, PlanArrayChunksSmallPlanIsOneChunkWithUnitIds) {
  const auto chunks = PlanArrayChunks({7, 1, 2, 2, 3}, 1001);
  ASSERT_EQ(chunks.size(), 1u);
  EXPECT_EQ(chunks[0].base, 0u);
  EXPECT_EQ(chunks[0].indices, (std::vector<uint32_t>{1, 2, 3, 7}));
  EXPECT_TRUE(PlanArrayChunks({}, 1001).empty());
}

TEST(Slurm, PlanArrayChunksKeepsIndicesBelowMaxArraySize) {
  // MaxArraySize 10: indices 0..9 only; unit 25 -> base 20, index 5.
  const auto chunks = PlanArrayChunks({0, 9, 10, 11, 25, 9}, 10);
  ASSERT_EQ(chunks.size(), 3u);
  EXPECT_EQ(chunks[0].base, 0u);
  EXPECT_EQ(chunks[0].indices, (std::vector<uint32_t>{0, 9}));
  EXPECT_EQ(chunks[1].base, 10u);
  EXPECT_EQ(chunks[1].indices, (std::vector<uint32_t>{0, 1}));
  EXPECT_EQ(chunks[2].base, 20u);
  EXPECT_EQ(chunks[2].indices, (std::vector<uint32_t>{5}));
  for (const auto& c : chunks) {
    for (uint32_t i : c.indices) EXPECT_LT(i, 10u);
  }
}

TEST(Slurm, PendingUnitsAreTheIncompleteOnes) {
  const std::vector<bool> complete = {true, false, true, true, false, false};
  const auto pending = PendingUnits(6, [&](uint32_t u) { return complete[u]; });
  EXPECT_EQ(pending, (std::vector<uint32_t>{1, 4, 5}));
  EXPECT_EQ(FormatArrayRanges(pending), "1,4-5");
  EXPECT_TRUE(PendingUnits(3, [](uint32_t) { return true; }).empty());
}

TEST(Slurm, SlurmTimeFormats) {
  for (const char* t : {"30", "30:00", "1:00:00", "2-0", "2-12:00", "2-12:00:00", "UNLIMITED"}) {
    EXPECT_TRUE(IsValidSlurmTime(t)) << t;
  }
  for (const char* t : {"", "1h", "1:00:00:00", "-5", "1-", "a:b", "1 :00"}) {
    EXPECT_FALSE(IsValidSlurmTime(t)) << t;
  }
}

TEST(Slurm, OptionsCheck) {
  SlurmOptions ok;
  ok.partition = "gpu-short";
  ok.time_limit = "0:30:00";
  ok.max_parallel = 8;
  ok.mem_per_task = "2G";
  ok.sbatch_args = {"--account=hands"};
  EXPECT_TRUE(ok.Check());

  SlurmOptions bad_time = ok;
  bad_time.time_limit = "half an hour";
  EXPECT_FALSE(bad_time.Check());
  SlurmOptions bad_partition = ok;
  bad_partition.partition = "a b";
  EXPECT_FALSE(bad_partition.Check());
  SlurmOptions bad_parallel = ok;
  bad_parallel.max_parallel = -1;
  EXPECT_FALSE(bad_parallel.Check());
  SlurmOptions bad_arg = ok;
  bad_arg.sbatch_args = {"account=hands"};
  EXPECT_FALSE(bad_arg.Check());
  SlurmOptions bad_mem = ok;
  bad_mem.mem_per_task = "lots";
  EXPECT_FALSE(bad_mem.Check());
}

TEST(Slurm, ShellQuote) {
  EXPECT_EQ(ShellQuote("abc"), "'abc'");
  EXPECT_EQ(ShellQuote("it's"), "'it'\\''s'");
  EXPECT_EQ(FormatCommand({"sbatch", "--array=0-3%2", "/a b/c"}), "sbatch --array=0-3%2 '/a b/c'");
}

TEST(Slurm, RunCommandCapturesOutputAndExitCode) {
  auto ok = RunCommand({"sh", "-c", "echo out; echo err >&2; exit 3"});
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(ok->out, "out\n");
  EXPECT_EQ(ok->err, "err\n");
  EXPECT_EQ(ok->exit_code, 3);
  auto missing = RunCommand({"handdb-no-such-program-xyz"});
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kExternalToolFailed);
  EXPECT_NE(missing.status().message().find("handdb-no-such-program-xyz"), std::string::npos);
}

TEST(Slurm, ParseScontrolJobs) {
  const std::string text =
      "JobId=8 ArrayJobId=5 ArrayTaskId=1 JobName=wrap UserId=root(0) JobState=FAILED "
      "Reason=NonZeroExitCode Dependency=(null) ExitCode=3:0 StdOut=/tmp/f-1.txt Power=\n"
      "JobId=5 ArrayJobId=5 ArrayTaskId=2-3 JobName=wrap JobState=PENDING Reason=None "
      "ExitCode=0:0\n"
      "JobId=6 JobName=final JobState=CANCELLED Reason=DependencyNeverSatisfied ExitCode=0:0\n";
  const auto jobs = ParseScontrolJobs(text);
  ASSERT_EQ(jobs.size(), 3u);
  EXPECT_EQ(jobs[0].job_id, "8");
  EXPECT_EQ(jobs[0].array_job_id, "5");
  EXPECT_EQ(jobs[0].array_task_id, 1);
  EXPECT_EQ(jobs[0].state, "FAILED");
  EXPECT_EQ(jobs[0].exit_code, "3:0");
  EXPECT_EQ(jobs[0].std_out, "/tmp/f-1.txt");
  EXPECT_EQ(jobs[1].array_task_id, -1);  // a pending range, not one task
  EXPECT_EQ(jobs[1].state, "PENDING");
  EXPECT_EQ(jobs[2].array_job_id, "");
  EXPECT_EQ(jobs[2].reason, "DependencyNeverSatisfied");
  EXPECT_TRUE(IsFinishedJobState("CANCELLED"));
  EXPECT_TRUE(IsFinishedJobState("TIMEOUT"));
  EXPECT_FALSE(IsFinishedJobState("PENDING"));
  EXPECT_FALSE(IsFinishedJobState("COMPLETING"));
}

TEST(Slurm, SubmissionRecordRoundTrip) {
  TempDir tmp;
  SlurmSubmission sub;
  sub.array_job_ids = {"12", "13"};
  sub.chunk_bases = {0, 1001};
  sub.final_job_id = "14";
  sub.db_dir = "/shared/db";
  sub.units = {1, 2, 1003};
  sub.sbatch_commands = {{"sbatch", "--parsable", "x"}};
  ASSERT_TRUE(WriteSubmissionRecord(tmp.path() / "jobs.json", sub).ok());
  auto back = ReadSubmissionRecord(tmp.path() / "jobs.json");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->array_job_ids, sub.array_job_ids);
  EXPECT_EQ(back->chunk_bases, sub.chunk_bases);
  EXPECT_EQ(back->final_job_id, "14");
  EXPECT_EQ(back->db_dir, "/shared/db");
  EXPECT_EQ(back->units, sub.units);
  ASSERT_TRUE(WriteFileAtomic(tmp.path() / "bad.json", "{\"format\": \"x\"}").ok());
  auto bad = ReadSubmissionRecord(tmp.path() / "bad.json");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("bad.json"), std::string::npos);
}

TEST(Slurm, FormatUnitFailure) {
  EXPECT_EQ(FormatUnitFailure({3, "TIMEOUT", "/r/slurm/logs/u00003.log"}),
            "unit 3: TIMEOUT; log: /r/slurm/logs/u00003.log");
}

}  // namespace
}  // namespace handdb
