#include "base/sha256.h"

#include <nettle/sha2.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <vector>

#include "base/hex.h"

namespace handdb {

Sha256::Sha256() : ctx_(std::make_unique<sha256_ctx>()) { sha256_init(ctx_.get()); }

Sha256::~Sha256() = default;

void Sha256::Update(const void* data, size_t size) {
  sha256_update(ctx_.get(), size, static_cast<const uint8_t*>(data));
}

std::string Sha256::HexDigest() {
  uint8_t digest[SHA256_DIGEST_SIZE];
  sha256_digest(ctx_.get(), sizeof(digest), digest);
  return HexBytes(digest, sizeof(digest));
}

std::string Sha256Hex(std::string_view data) {
  Sha256 sha;
  sha.Update(data);
  return sha.HexDigest();
}

Result<std::string> Sha256File(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return Status(StatusCode::kNotFound, path.string() + ": no such file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in)
    return Status(StatusCode::kIoError, path.string() + ": cannot open: " + std::strerror(errno));
  Sha256 sha;
  std::vector<char> buf(1 << 16);
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    const std::streamsize n = in.gcount();
    if (n > 0) sha.Update(buf.data(), static_cast<size_t>(n));
  }
  if (in.bad()) return Status(StatusCode::kIoError, path.string() + ": read failed");
  return sha.HexDigest();
}

}  // namespace handdb
