#include "base/thread_pool.h"

#include <gtest/gtest.h>

#include <atomic>
#include <mutex>
#include <numeric>
#include <set>
#include <stdexcept>
#include <system_error>
#include <vector>

namespace handdb {
namespace {

TEST(ThreadPool, ResolveNumThreads) {
  EXPECT_EQ(ResolveNumThreads(3), 3);
  EXPECT_GE(ResolveNumThreads(-1), 1);
  EXPECT_EQ(ResolveNumThreads(0), ResolveNumThreads(-1));
  EXPECT_EQ(ThreadPool(2).NumThreads(), 2);
}

TEST(ThreadPool, FuturesCarryResultsAndRethrow) {
  ThreadPool pool(3);
  std::vector<std::future<int>> futures;
  for (int i = 0; i < 100; ++i) futures.push_back(pool.AddTask([](int x) { return x * x; }, i));
  for (int i = 0; i < 100; ++i) EXPECT_EQ(futures[i].get(), i * i);
  auto bad = pool.AddTask([] { throw std::runtime_error("boom"); });
  EXPECT_THROW(bad.get(), std::runtime_error);
}

TEST(ThreadPool, DestructorRunsQueuedTasks) {
  std::atomic<int> ran{0};
  {
    ThreadPool pool(2);
    for (int i = 0; i < 50; ++i) pool.AddTask([&ran] { ++ran; });
  }
  EXPECT_EQ(ran.load(), 50);
}

TEST(ParallelFor, VisitsEveryIndexOnceWithDistinctWorkers) {
  for (int workers : {1, 2, 4}) {
    std::vector<std::atomic<int>> hits(1000);
    std::vector<std::atomic<int>> busy(static_cast<size_t>(workers));
    ParallelFor(hits.size(), workers, [&](size_t i, int worker) {
      EXPECT_GE(worker, 0);
      EXPECT_LT(worker, workers);
      EXPECT_EQ(busy[static_cast<size_t>(worker)]++, 0);  // no two workers share an index
      ++hits[i];
      --busy[static_cast<size_t>(worker)];
      return true;
    });
    for (auto& h : hits) ASSERT_EQ(h.load(), 1);
  }
}

TEST(ParallelFor, StopsAndRethrows) {
  std::atomic<size_t> ran{0};
  ParallelFor(100000, 2, [&](size_t i, int) {
    ++ran;
    return i < 10;
  });
  EXPECT_LT(ran.load(), 100000u);
  ThreadPool pool(3);
  EXPECT_THROW(ParallelFor(
                   100,
                   4,
                   [](size_t i, int) {
                     if (i == 7) throw std::logic_error("seven");
                     return true;
                   },
                   &pool),
               std::logic_error);
}

TEST(ParallelForStatus, FirstErrorAndCancel) {
  EXPECT_TRUE(ParallelForStatus(50, 2, nullptr, [](size_t) { return Status(); }).ok());
  const Status s = ParallelForStatus(1000, 1, nullptr, [](size_t i) {
    return i == 5 ? Status(StatusCode::kIoError, "five") : Status();
  });
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_EQ(s.message(), "five");
  std::atomic<bool> cancel{true};
  std::atomic<int> ran{0};
  const Status c = ParallelForStatus(10, 2, &cancel, [&](size_t) {
    ++ran;
    return Status();
  });
  EXPECT_EQ(c.code(), StatusCode::kCancelled);
  EXPECT_EQ(ran.load(), 0);
}

// A pool caps a loop's workers: a loop asking for more runs on the pool's threads and the
// caller, never on threads of its own.
TEST(ParallelFor, APoolCapsTheWorkers) {
  ThreadPool pool(1);
  std::set<int> workers;
  std::mutex mu;
  ParallelFor(
      1000,
      8,
      [&](size_t, int worker) {
        std::lock_guard<std::mutex> lock(mu);
        workers.insert(worker);
        return true;
      },
      &pool);
  EXPECT_LE(workers.size(), 2u);
  for (int w : workers) EXPECT_LT(w, 2);
}

TEST(ThreadPool, MaxNumThreadsIsBounded) {
  EXPECT_GE(MaxNumThreads(), 4);
  EXPECT_LE(MaxNumThreads(), 256);
}

// When the system refuses a thread, construction joins what it started and fails: Create
// returns the error, and nothing is left running or waiting.
TEST(ThreadPool, AThreadThatCannotStartIsAnError) {
  SetThreadStartLimitForTesting(2);
  EXPECT_THROW(ThreadPool pool(4), std::system_error);
  auto pool = ThreadPool::Create(4);
  SetThreadStartLimitForTesting(-1);
  ASSERT_FALSE(pool.ok());
  EXPECT_EQ(pool.status().code(), StatusCode::kIoError);
  EXPECT_NE(pool.status().message().find("cannot start 4 worker threads"), std::string::npos)
      << pool.status().message();
  auto fine = ThreadPool::Create(2);
  ASSERT_TRUE(fine.ok());
  EXPECT_EQ((*fine)->NumThreads(), 2);
}

}  // namespace
}  // namespace handdb
