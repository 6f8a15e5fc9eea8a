#include "base/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

#include "base/hex.h"

namespace handdb {
namespace {

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
}

Status AtomicFileWriter::Open(const std::filesystem::path& target) {
  THROW_CHECK_MSG(fd_ < 0, "AtomicFileWriter::Open called twice");
  target_ = target;
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
    Status s = Errno("cannot create temp file", temp_);
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
      return Errno("write failed", temp_);
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
  const char* p = static_cast<const char*>(data);
  size_t left = size;
  while (left > 0) {
    ssize_t n = ::pwrite(fd_, p, left, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      return Errno("pwrite failed", temp_);
    }
    p += n;
    offset += static_cast<uint64_t>(n);
    left -= static_cast<size_t>(n);
  }
  return Status::Ok();
}

Status AtomicFileWriter::Commit() {
  THROW_CHECK_MSG(fd_ >= 0, "AtomicFileWriter::Commit before Open");
  if (::fsync(fd_) != 0) return Errno("fsync failed", temp_);
  if (::close(fd_) != 0) {
    fd_ = -1;
    return Errno("close failed", temp_);
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

Result<std::string> ReadFileToString(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return Status(StatusCode::kNotFound, path.string() + ": no such file");
  }
  if (std::filesystem::is_directory(path, ec)) {
    return Status(StatusCode::kIoError, path.string() + ": is a directory, expected a file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status(StatusCode::kIoError, path.string() + ": cannot open for reading");
  std::ostringstream os;
  os << in.rdbuf();
  if (in.bad()) return Status(StatusCode::kIoError, path.string() + ": read failed");
  return os.str();
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
