#include "base/image_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <string>
#include <string_view>

#include "base/atomic_file.h"
#include "base/endian.h"

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

uint32_t BigEndian(std::string_view b, size_t at, int bytes) {
  uint32_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | static_cast<uint8_t>(b[at + i]);
  return v;
}

// The frame size of the first SOFn segment, walking the marker segments from the start.
std::optional<ImageSize> JpegSize(int fd) {
  off_t at = 2;  // after SOI
  for (int segments = 0; segments < 4096; ++segments) {
    const std::string m = ReadAt(fd, at, 9);
    if (m.size() < 4 || static_cast<uint8_t>(m[0]) != 0xFF) return std::nullopt;
    const auto marker = static_cast<uint8_t>(m[1]);
    if (marker == 0xFF) {  // fill byte
      ++at;
      continue;
    }
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {  // no length
      at += 2;
      continue;
    }
    if (marker == 0xD9 || marker == 0xDA) return std::nullopt;  // EOI / start of scan
    const bool sof =
        marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (sof) {
      if (m.size() < 9) return std::nullopt;
      return ImageSize{BigEndian(m, 7, 2), BigEndian(m, 5, 2), "JPEG"};
    }
    at += 2 + static_cast<off_t>(BigEndian(m, 2, 2));
  }
  return std::nullopt;
}

// "P5\n# comment\n300 200\n255\n": the first two numbers after the magic.
std::optional<ImageSize> PnmSize(std::string_view h) {
  size_t i = 2;
  uint64_t v[2] = {0, 0};
  for (uint64_t& out : v) {
    while (i < h.size() && (std::isspace(static_cast<unsigned char>(h[i])) || h[i] == '#')) {
      if (h[i] == '#') {
        while (i < h.size() && h[i] != '\n') ++i;
      } else {
        ++i;
      }
    }
    const size_t start = i;
    while (i < h.size() && std::isdigit(static_cast<unsigned char>(h[i])) && i - start < 12) {
      out = out * 10 + static_cast<uint64_t>(h[i] - '0');
      ++i;
    }
    if (i == start) return std::nullopt;
  }
  return ImageSize{v[0], v[1], "PNM"};
}

std::optional<ImageSize> SizeFromHeader(int fd) {
  const std::string head = ReadAt(fd, 0, 512);
  const std::string_view h(head);
  if (h.size() >= 24 && h.substr(0, 8) == std::string_view("\x89PNG\r\n\x1A\n", 8) &&
      h.substr(12, 4) == "IHDR") {
    return ImageSize{BigEndian(h, 16, 4), BigEndian(h, 20, 4), "PNG"};
  }
  if (h.size() >= 3 && h.substr(0, 3) == std::string_view("\xFF\xD8\xFF", 3)) return JpegSize(fd);
  if (h.size() >= 3 && h[0] == 'P' && h[1] >= '1' && h[1] <= '6' &&
      std::isspace(static_cast<unsigned char>(h[2]))) {
    return PnmSize(h);
  }
  if (h.size() >= 26 && h.substr(0, 2) == "BM") {
    const auto height = static_cast<int32_t>(LoadLittleEndian<uint32_t>(h.data() + 22));
    return ImageSize{LoadLittleEndian<uint32_t>(h.data() + 18),
                     static_cast<uint64_t>(height < 0 ? -static_cast<int64_t>(height) : height),
                     "BMP"};
  }
  return std::nullopt;
}

}  // namespace

std::optional<ImageSize> ReadImageSize(const std::filesystem::path& path) {
  if (!CheckRegularFile(path).ok()) return std::nullopt;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return std::nullopt;
  std::optional<ImageSize> size = SizeFromHeader(fd);
  ::close(fd);
  return size;
}

Status CheckImageFileComplete(const std::filesystem::path& path,
                              uint64_t max_pixels,
                              uint64_t max_jpeg_pixels) {
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
  const std::optional<ImageSize> size = SizeFromHeader(fd);
  ::close(fd);
  // Refused from the header, before a decoder allocates width x height.
  const uint64_t limit =
      size && std::string_view(size->format) == "JPEG" ? max_jpeg_pixels : max_pixels;
  if (size && size->width * size->height > limit) {
    return Status(StatusCode::kBadImage,
                  name + ": " + std::to_string(size->width) + " x " + std::to_string(size->height) +
                      " pixels (" + size->format + " header), more than the " +
                      std::to_string(limit) + " (" + std::to_string(limit >> 20) + " Mpx) allowed");
  }
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
