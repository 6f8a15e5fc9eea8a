// One thread pool for the project (after COLMAP's util/threading.h) and the parallel loop built on
// it:
//   ThreadPool pool(n);
//   futures.push_back(pool.AddTask(Work, i));
//   futures[i].get();  // the task's result; rethrows what the task threw
#pragma once

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <exception>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <queue>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include "base/status.h"

namespace handdb {

// The number of threads a `num_threads` option asks for: itself when >= 1, otherwise (-1, 0) the
// hardware concurrency, at least 1.
int ResolveNumThreads(int num_threads);

// The most threads a `num_threads` option may ask for: 4x the cores, at most 256. More gains
// nothing on this machine and a typo (--threads 100000) would otherwise try to start them all.
int MaxNumThreads();

// Tests only: pools constructed from now on start at most `n` threads each, then fail as the
// system does when it refuses a thread (std::system_error); -1 lifts the limit.
void SetThreadStartLimitForTesting(int n);

class ThreadPool {
 public:
  // ResolveNumThreads(num_threads) worker threads, started now. When the system refuses a
  // thread, the ones already started are joined and the std::system_error is rethrown.
  explicit ThreadPool(int num_threads = -1);
  // The same as a Result: kIoError naming how many threads started when one could not be.
  static Result<std::unique_ptr<ThreadPool>> Create(int num_threads);
  // Runs every task already added, then joins the workers.
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int NumThreads() const { return static_cast<int>(workers_.size()); }

  // Queues fn(args...) (arguments copied or moved in); the future yields its result or rethrows.
  template <class Fn, class... Args>
  auto AddTask(Fn&& fn, Args&&... args)
      -> std::future<std::invoke_result_t<std::decay_t<Fn>, std::decay_t<Args>...>> {
    using R = std::invoke_result_t<std::decay_t<Fn>, std::decay_t<Args>...>;
    auto task = std::make_shared<std::packaged_task<R()>>(
        [fn = std::forward<Fn>(fn), ... args = std::forward<Args>(args)]() mutable {
          return std::invoke(fn, args...);
        });
    std::future<R> future = task->get_future();
    Push([task] { (*task)(); });
    return future;
  }

 private:
  void Push(std::function<void()> task);
  void WorkerLoop();
  void Stop();  // runs what is queued, then joins the workers

  std::vector<std::thread> workers_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::queue<std::function<void()>> tasks_;
  bool stopping_ = false;
};

// Runs fn(i, worker) for every i in [0, n) on min(num_workers, n) workers that take indices in
// increasing order from a shared counter; worker 0 is the calling thread, workers 1.. run on
// `pool` (at most its NumThreads() of them: a pool caps the workers, so one pool serves loops
// of any width), or on a pool made for this call when `pool` is null. `worker` is in [0,
// num_workers) and no two workers share one, so it can index per-worker scratch. fn returns false
// to stop every worker from starting another index. The first exception thrown by fn is rethrown
// here, after every worker has stopped.
template <class Fn>
void ParallelFor(size_t n, int num_workers, Fn&& fn, ThreadPool* pool = nullptr) {
  int workers =
      static_cast<int>(std::min<size_t>(std::max(num_workers, 1), std::max<size_t>(n, 1)));
  if (pool != nullptr) workers = std::min(workers, pool->NumThreads() + 1);
  std::atomic<size_t> next{0};
  std::atomic<bool> stop{false};
  std::exception_ptr error;
  std::mutex error_mu;
  auto work = [&](int worker) {
    try {
      while (!stop.load(std::memory_order_relaxed)) {
        const size_t i = next.fetch_add(1, std::memory_order_relaxed);
        if (i >= n) break;
        if (!fn(i, worker)) stop.store(true, std::memory_order_relaxed);
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mu);
      if (!error) error = std::current_exception();
      stop.store(true);
    }
  };
  if (workers > 1) {
    std::optional<ThreadPool> own;
    if (pool == nullptr) pool = &own.emplace(workers - 1);
    std::vector<std::future<void>> done;
    done.reserve(static_cast<size_t>(workers - 1));
    for (int w = 1; w < workers; ++w) done.push_back(pool->AddTask(work, w));
    work(0);
    for (auto& f : done) f.get();  // work() catches everything, so get() only waits
  } else {
    work(0);
  }
  if (error) std::rethrow_exception(error);
}

// ParallelFor for work that can fail: fn(i) returns a Status. After the first non-OK status, or
// once *cancel (may be null) is true, no further index starts; returns that first status
// (kCancelled "cancelled" for a cancel), OK when every index ran. Exceptions are rethrown as above.
template <class Fn>
Status ParallelForStatus(size_t n,
                         int num_workers,
                         const std::atomic<bool>* cancel,
                         Fn&& fn,
                         ThreadPool* pool = nullptr) {
  std::mutex mu;
  Status first_error;
  ParallelFor(
      n,
      num_workers,
      [&](size_t i, int) {
        if (cancel != nullptr && cancel->load()) {
          std::lock_guard<std::mutex> lock(mu);
          if (first_error.ok()) first_error = Status(StatusCode::kCancelled, "cancelled");
          return false;
        }
        Status s = fn(i);
        if (s.ok()) return true;
        std::lock_guard<std::mutex> lock(mu);
        if (first_error.ok()) first_error = std::move(s);
        return false;
      },
      pool);
  return first_error;
}

}  // namespace handdb
