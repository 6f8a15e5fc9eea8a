#include "base/sha256.h"

#include <openssl/evp.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <vector>

#include "base/hex.h"

namespace handdb {

void Sha256::FreeContext::operator()(evp_md_ctx_st* ctx) const { EVP_MD_CTX_free(ctx); }

Sha256::Sha256() : ctx_(EVP_MD_CTX_new()) {
  THROW_CHECK_MSG(ctx_ != nullptr, "EVP_MD_CTX_new failed");
  THROW_CHECK_MSG(EVP_DigestInit_ex(ctx_.get(), EVP_sha256(), nullptr) == 1,
                  "EVP_DigestInit_ex(sha256) failed");
}

Sha256::~Sha256() = default;

void Sha256::Update(const void* data, size_t size) {
  THROW_CHECK_MSG(EVP_DigestUpdate(ctx_.get(), data, size) == 1, "EVP_DigestUpdate failed");
}

std::string Sha256::HexDigest() {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int size = 0;
  THROW_CHECK_MSG(EVP_DigestFinal_ex(ctx_.get(), digest, &size) == 1, "EVP_DigestFinal_ex failed");
  return HexBytes(digest, size);
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
