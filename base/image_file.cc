#include "base/image_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <string>
#include <string_view>

#include "base/atomic_file.h"

namespace handdb {
namespace {

constexpr size_t kTailBytes = 4096;

// Bytes [offset, offset + size) of the open file (fewer at its end); empty on a read error.
std::string ReadAt(int fd, off_t offset, size_t size) {
  std::string buf(size, '\0');
  size_t got = 0;
  while (got < size) {
    const ssize_t n = ::pread(fd, buf.data() + got, size - got, offset + static_cast<off_t>(got));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    got += static_cast<size_t>(n);
  }
  buf.resize(got);
  return buf;
}

}  // namespace

Status CheckImageFileComplete(const std::filesystem::path& path) {
  if (Status s = CheckRegularFile(path); !s.ok()) return s;
  const std::string name = path.string();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    return Status(StatusCode::kIoError, name + ": cannot open: " + std::strerror(errno));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0) st.st_size = 0;
  const std::string head = ReadAt(fd, 0, 8);
  const off_t tail_at = std::max<off_t>(0, st.st_size - static_cast<off_t>(kTailBytes));
  const std::string tail = ReadAt(fd, tail_at, kTailBytes);
  ::close(fd);
  const std::string_view h(head);
  if (h.size() >= 3 && h.substr(0, 3) == std::string_view("\xFF\xD8\xFF", 3)) {
    // In entropy-coded data every FF is followed by 00 or a restart marker, so FF D9 is the EOI.
    if (tail.find(std::string_view("\xFF\xD9", 2)) == std::string::npos) {
      return Status(StatusCode::kBadImage, name + ": truncated JPEG (no end-of-image marker)");
    }
  } else if (h.size() >= 8 && h == std::string_view("\x89PNG\r\n\x1A\n", 8)) {
    // The IEND chunk: zero length, type "IEND", its fixed CRC.
    if (tail.find(std::string_view("\0\0\0\0IEND\xAE\x42\x60\x82", 12)) == std::string::npos) {
      return Status(StatusCode::kBadImage, name + ": truncated PNG (no IEND chunk)");
    }
  }
  return Status::Ok();
}

}  // namespace handdb
