#include "base/mapped_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <string>
#include <utility>

#include "base/atomic_file.h"

namespace handdb {
namespace {

// Closes the descriptor on every return path of Open (the mapping outlives it).
struct FdCloser {
  int fd;
  ~FdCloser() { ::close(fd); }
};

}  // namespace

Result<MappedFile> MappedFile::Open(const std::filesystem::path& path, Advice advice) {
  const std::string name = path.string();
  // Refuse FIFOs and devices before open() (which would block on a FIFO); O_NONBLOCK and the
  // fstat below cover a path swapped in between.
  if (Status s = CheckRegularFile(path); !s.ok()) return s;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    const StatusCode code = errno == ENOENT ? StatusCode::kNotFound : StatusCode::kIoError;
    return Status(code, name + ": cannot open: " + std::strerror(errno));
  }
  const FdCloser closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    return Status(StatusCode::kIoError, name + ": fstat failed: " + std::strerror(errno));
  }
  if (!S_ISREG(st.st_mode)) return Status(StatusCode::kIoError, name + ": not a regular file");
  MappedFile file;
  const auto size = static_cast<size_t>(st.st_size);
  if (size == 0) return file;
  void* map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  if (map == MAP_FAILED) {
    return Status(
        StatusCode::kIoError,
        name + ": mmap of " + std::to_string(size) + " bytes failed: " + std::strerror(errno));
  }
  file.map_ = map;
  file.size_ = size;
  file.Advise(0, size, advice);
  return file;
}

void MappedFile::Advise(uint64_t begin, uint64_t end, Advice advice) const {
  THROW_CHECK_EQ(begin % 4096, 0u);
  end = std::min<uint64_t>(end, size_);
  if (map_ == nullptr || end <= begin) return;
  const int flag = advice == Advice::kSequential ? MADV_SEQUENTIAL
                   : advice == Advice::kDontNeed ? MADV_DONTNEED
                                                 : MADV_NORMAL;
  ::madvise(static_cast<uint8_t*>(map_) + begin, end - begin, flag);  // a hint: errors ignored
}

MappedFile::~MappedFile() { Reset(); }

MappedFile::MappedFile(MappedFile&& other) noexcept
    : map_(std::exchange(other.map_, nullptr)), size_(std::exchange(other.size_, 0)) {}

MappedFile& MappedFile::operator=(MappedFile&& other) noexcept {
  if (this != &other) {
    Reset();
    map_ = std::exchange(other.map_, nullptr);
    size_ = std::exchange(other.size_, 0);
  }
  return *this;
}

void MappedFile::Reset() {
  if (map_ != nullptr) ::munmap(map_, size_);
  map_ = nullptr;
  size_ = 0;
}

}  // namespace handdb
