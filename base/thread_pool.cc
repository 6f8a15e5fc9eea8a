#include "base/thread_pool.h"

#include <algorithm>
#include <cerrno>
#include <string>
#include <system_error>

namespace handdb {

int ResolveNumThreads(int num_threads) {
  if (num_threads >= 1) return num_threads;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

namespace {
std::atomic<int> thread_start_limit{-1};
}  // namespace

int MaxNumThreads() {
  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  return std::min(256, 4 * cores);
}

void SetThreadStartLimitForTesting(int n) { thread_start_limit.store(n); }

ThreadPool::ThreadPool(int num_threads) {
  const int n = ResolveNumThreads(num_threads);
  const int limit = thread_start_limit.load();
  workers_.reserve(static_cast<size_t>(n));
  try {
    for (int i = 0; i < n; ++i) {
      if (limit >= 0 && i >= limit) {
        throw std::system_error(std::make_error_code(std::errc::resource_unavailable_try_again),
                                "thread start limit (test)");
      }
      workers_.emplace_back([this] { WorkerLoop(); });
    }
  } catch (...) {
    // A destroyed joinable std::thread terminates the process: stop and join what started.
    Stop();
    throw;
  }
}

Result<std::unique_ptr<ThreadPool>> ThreadPool::Create(int num_threads) {
  try {
    return std::make_unique<ThreadPool>(num_threads);
  } catch (const std::system_error& e) {
    return Status(StatusCode::kIoError,
                  "cannot start " + std::to_string(ResolveNumThreads(num_threads)) +
                      " worker threads: " + e.what() + " (try fewer --threads)");
  }
}

ThreadPool::~ThreadPool() { Stop(); }

void ThreadPool::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  for (auto& t : workers_) t.join();
  workers_.clear();
}

void ThreadPool::Push(std::function<void()> task) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    THROW_CHECK_MSG(!stopping_, "ThreadPool::AddTask on a pool being destroyed");
    tasks_.push(std::move(task));
  }
  cv_.notify_one();
}

void ThreadPool::WorkerLoop() {
  while (true) {
    std::function<void()> task;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [this] { return stopping_ || !tasks_.empty(); });
      if (tasks_.empty()) return;  // stopping, and everything queued has run
      task = std::move(tasks_.front());
      tasks_.pop();
    }
    task();  // a packaged_task: what the work throws goes to its future
  }
}

}  // namespace handdb
