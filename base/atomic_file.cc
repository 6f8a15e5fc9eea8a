#include "base/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <random>
#include <utility>

#include "base/hex.h"

namespace handdb {
namespace {

// Named by the file the caller asked for, not its temp file: "out.json: write failed: No space
// left on device", one line naming the file and the problem.
Status Errno(const std::string& what, const std::filesystem::path& path) {
  return Status(StatusCode::kIoError, path.string() + ": " + what + ": " + std::strerror(errno));
}

std::string RandomSuffix() {
  static thread_local std::mt19937_64 rng(std::random_device{}() ^
                                          (static_cast<uint64_t>(getpid()) << 32));
  return Hex64(rng());
}

}  // namespace

AtomicFileWriter::~AtomicFileWriter() { Abort(); }

void AtomicFileWriter::Abort() {
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
  if (!committed_ && !temp_.empty()) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
  temp_.clear();
  streamed_ = false;
}

Status AtomicFileWriter::OpenStreamed() {
  // O_NONBLOCK: a FIFO nobody reads fails at once (ENXIO) instead of blocking; blocking writes
  // are restored below.
  fd_ = ::open(target_.c_str(), O_WRONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
  if (fd_ < 0) {
    if (errno == ENXIO) {
      return Status(StatusCode::kIoError, target_.string() + ": a FIFO with no reader");
    }
    return Errno("cannot open for writing", target_);
  }
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || S_ISREG(st.st_mode) || S_ISDIR(st.st_mode)) {
    // Swapped for a regular file since the stat: take the atomic path after all.
    ::close(fd_);
    fd_ = -1;
    return Status(StatusCode::kIoError,
                  target_.string() + ": changed while being opened for writing");
  }
  const int flags = ::fcntl(fd_, F_GETFL);
  if (flags >= 0) ::fcntl(fd_, F_SETFL, flags & ~O_NONBLOCK);
  size_ = 0;
  committed_ = false;
  streamed_ = true;
  return Status::Ok();
}

Status AtomicFileWriter::Open(const std::filesystem::path& target) {
  THROW_CHECK_MSG(fd_ < 0, "AtomicFileWriter::Open called twice");
  target_ = target;
  struct stat st {};
  if (::stat(target.c_str(), &st) == 0 && !S_ISREG(st.st_mode) && !S_ISDIR(st.st_mode)) {
    return OpenStreamed();
  }
  std::filesystem::path dir = target.parent_path();
  if (dir.empty()) dir = ".";
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    return Status(StatusCode::kIoError,
                  dir.string() + ": cannot create directory: " + ec.message());
  }
  temp_ = dir / (target.filename().string() + ".tmp-" + RandomSuffix());
  fd_ = ::open(temp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd_ < 0) {
    Status s = Errno("cannot create temp file " + temp_.filename().string(), target);
    temp_.clear();
    return s;
  }
  size_ = 0;
  committed_ = false;
  return Status::Ok();
}

Status AtomicFileWriter::Write(const void* data, size_t size) {
  THROW_CHECK_MSG(fd_ >= 0, "AtomicFileWriter::Write before Open");
  const char* p = static_cast<const char*>(data);
  size_t left = size;
  while (left > 0) {
    ssize_t n = ::write(fd_, p, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      return Errno("write failed", target_);
    }
    p += n;
    left -= static_cast<size_t>(n);
  }
  size_ += size;
  return Status::Ok();
}

Status AtomicFileWriter::WriteAt(uint64_t offset, const void* data, size_t size) {
  THROW_CHECK_MSG(fd_ >= 0, "AtomicFileWriter::WriteAt before Open");
  THROW_CHECK_LE(offset + size, size_);
  if (streamed_) {
    return Status(StatusCode::kIoError,
                  target_.string() + ": not a regular file (this output cannot be streamed)");
  }
  const char* p = static_cast<const char*>(data);
  size_t left = size;
  while (left > 0) {
    ssize_t n = ::pwrite(fd_, p, left, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      return Errno("pwrite failed", target_);
    }
    p += n;
    offset += static_cast<uint64_t>(n);
    left -= static_cast<size_t>(n);
  }
  return Status::Ok();
}

Status AtomicFileWriter::Commit() {
  THROW_CHECK_MSG(fd_ >= 0, "AtomicFileWriter::Commit before Open");
  if (streamed_) {
    const int fd = std::exchange(fd_, -1);
    if (::close(fd) != 0 && errno != EINTR) return Errno("close failed", target_);
    committed_ = true;
    return Status::Ok();
  }
  if (::fsync(fd_) != 0) return Errno("fsync failed", target_);
  if (::close(fd_) != 0) {
    fd_ = -1;
    return Errno("close failed", target_);
  }
  fd_ = -1;
  if (::rename(temp_.c_str(), target_.c_str()) != 0) return Errno("rename failed", target_);
  committed_ = true;
  std::filesystem::path dir = target_.parent_path();
  return SyncDirectory(dir.empty() ? std::filesystem::path(".") : dir);
}

Status WriteFileAtomic(const std::filesystem::path& target, std::string_view data) {
  AtomicFileWriter w;
  HANDDB_RETURN_IF_ERROR(w.Open(target));
  HANDDB_RETURN_IF_ERROR(w.Write(data));
  return w.Commit();
}

Status CheckRegularFile(const std::filesystem::path& path) {
  const std::string name = path.string();
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    switch (errno) {
      case ENOENT:
      case ENOTDIR:
        return Status(StatusCode::kNotFound, name + ": no such file");
      case EACCES:
        return Status(StatusCode::kIoError, name + ": permission denied");
      case ELOOP:
        return Status(StatusCode::kIoError,
                      name + ": too many levels of symbolic links (a symlink loop?)");
      default:
        return Errno("cannot stat", path);
    }
  }
  if (S_ISDIR(st.st_mode)) {
    return Status(StatusCode::kIoError, name + ": is a directory, expected a file");
  }
  if (!S_ISREG(st.st_mode)) return Status(StatusCode::kIoError, name + ": not a regular file");
  // stat() needs only the directory's permissions; say so here rather than as a library's
  // "cannot read" later.
  if (::access(path.c_str(), R_OK) != 0 && errno == EACCES) {
    return Status(StatusCode::kIoError, name + ": permission denied");
  }
  return Status::Ok();
}

Result<std::string> ReadFileToString(const std::filesystem::path& path, uint64_t max_bytes) {
  if (Status s = CheckRegularFile(path); !s.ok()) return s;
  // O_NONBLOCK: if the path was swapped for a FIFO since the stat, open does not block either;
  // fstat on the descriptor is the check that counts.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    if (errno == EACCES) return Status(StatusCode::kIoError, path.string() + ": permission denied");
    return Errno("cannot open for reading", path);
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return Status(StatusCode::kIoError, path.string() + ": not a regular file");
  }
  if (static_cast<uint64_t>(st.st_size) > max_bytes) {
    ::close(fd);
    return Status(StatusCode::kIoError,
                  path.string() + ": " + std::to_string(st.st_size) + " bytes, more than the " +
                      std::to_string(max_bytes) + " allowed for this kind of file");
  }
  std::string text;
  text.reserve(static_cast<size_t>(st.st_size));
  char buf[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      Status s = Errno("read failed", path);
      ::close(fd);
      return s;
    }
    if (n == 0) break;
    text.append(buf, static_cast<size_t>(n));
    if (text.size() > max_bytes) {  // grew while we read
      ::close(fd);
      return Status(StatusCode::kIoError,
                    path.string() + ": more than the " + std::to_string(max_bytes) +
                        " bytes allowed for this kind of file");
    }
  }
  ::close(fd);
  return text;
}

Status SyncDirectory(const std::filesystem::path& dir) {
  int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return Errno("cannot open directory for fsync", dir);
  int rc = ::fsync(fd);
  ::close(fd);
  if (rc != 0) return Errno("fsync of directory failed", dir);
  return Status::Ok();
}

}  // namespace handdb
