// An exclusive advisory lock on a directory for one writer at a time (without it, two `generate`
// runs into one --out would both render everything). flock(2) on the directory
// itself, so no lock file appears in it; the kernel drops the lock when the process dies, so a
// killed run never leaves a stale lock behind.
#pragma once

#include <filesystem>

#include "base/status.h"

namespace handdb {

class DirectoryLock {
 public:
  // Takes the lock without waiting. `dir` must exist. kIoError names the directory: held by
  // another process ("<dir>: another handdb process is writing here (its lock is held); wait for
  // it to finish or use another directory"), or it cannot be opened.
  // The descriptor is close-on-exec: Blender workers and other children do not hold it.
  static Result<DirectoryLock> Acquire(const std::filesystem::path& dir);

  DirectoryLock() = default;
  ~DirectoryLock();
  DirectoryLock(DirectoryLock&& other) noexcept;
  DirectoryLock& operator=(DirectoryLock&& other) noexcept;
  DirectoryLock(const DirectoryLock&) = delete;
  DirectoryLock& operator=(const DirectoryLock&) = delete;

 private:
  explicit DirectoryLock(int fd) : fd_(fd) {}
  int fd_ = -1;
};

}  // namespace handdb
