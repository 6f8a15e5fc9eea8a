// Every file handdb writes appears atomically: written to a temp file in the same directory,
// fsync'ed, renamed over the target, and the directory fsync'ed. A crash leaves either the old
// file or the new one, never a half-written one; stale temp files are named "<target>.tmp-*".
//
// A target that exists and is not a regular file or a directory (a device such as /dev/null or
// /dev/stdout's pipe, a FIFO, a socket) is never renamed over: the bytes are streamed into it
// directly, as a shell redirection would, so `-o /dev/null` never replaces /dev/null.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "base/status.h"

namespace handdb {

class AtomicFileWriter {
 public:
  AtomicFileWriter() = default;
  ~AtomicFileWriter();  // removes the temp file unless Commit() succeeded
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;

  Status Open(const std::filesystem::path& target);
  Status Write(const void* data, size_t size);
  Status Write(std::string_view data) { return Write(data.data(), data.size()); }
  // Overwrites bytes already written (used to patch headers after streaming). kIoError on a
  // streamed target (a device or FIFO cannot be patched).
  Status WriteAt(uint64_t offset, const void* data, size_t size);
  uint64_t bytes_written() const { return size_; }
  // fsync + rename + fsync(dir); on a streamed target, close.
  Status Commit();
  // True when the target is a device, FIFO or socket written in place (no temp file).
  bool streamed() const { return streamed_; }
  void Abort();

  const std::filesystem::path& target() const { return target_; }
  const std::filesystem::path& temp_path() const { return temp_; }

 private:
  Status OpenStreamed();

  std::filesystem::path target_;
  std::filesystem::path temp_;
  int fd_ = -1;
  uint64_t size_ = 0;
  bool committed_ = false;
  bool streamed_ = false;
};

// Convenience: the whole content at once.
Status WriteFileAtomic(const std::filesystem::path& target, std::string_view data);

// Ok when `path` (symlinks followed) is a regular file, checked with stat() before anything opens
// it, so a FIFO, a device (/dev/zero, /dev/urandom) or a directory never blocks or floods a read.
// Errors name the path: kNotFound "no such file"; kIoError "permission denied", "symlink loop",
// "is a directory, expected a file", "not a regular file" (FIFO, socket, device).
Status CheckRegularFile(const std::filesystem::path& path);

// Reads a whole (small) regular file (CheckRegularFile first); kNotFound / kIoError name the path.
// A file larger than `max_bytes` is refused before it is read (kIoError "... bytes, more than the
// N allowed").
Result<std::string> ReadFileToString(const std::filesystem::path& path,
                                     uint64_t max_bytes = UINT64_MAX);

// fsync a directory (after creating/renaming entries in it).
Status SyncDirectory(const std::filesystem::path& dir);

}  // namespace handdb
