#include "base/thread_pool.h"

#include <algorithm>

namespace handdb {

int ResolveNumThreads(int num_threads) {
  if (num_threads >= 1) return num_threads;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

ThreadPool::ThreadPool(int num_threads) {
  const int n = ResolveNumThreads(num_threads);
  workers_.reserve(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) workers_.emplace_back([this] { WorkerLoop(); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  for (auto& t : workers_) t.join();
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
