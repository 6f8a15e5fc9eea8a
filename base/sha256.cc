#include "base/sha256.h"

#include <dlfcn.h>
#include <openssl/evp.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <mutex>
#include <vector>

#include "base/hex.h"

namespace handdb {
namespace {

// OpenSSL's libcrypto is opened on the first digest, not linked: its ~21,000 relocations were the
// largest share of every command's start (docs/decisions/0020), and only making a plan, a
// database or its rig's record digests anything.
struct Evp {
  decltype(&EVP_MD_CTX_new) ctx_new = nullptr;
  decltype(&EVP_MD_CTX_free) ctx_free = nullptr;
  decltype(&EVP_sha256) sha256 = nullptr;
  decltype(&EVP_DigestInit_ex) init = nullptr;
  decltype(&EVP_DigestUpdate) update = nullptr;
  decltype(&EVP_DigestFinal_ex) final_ex = nullptr;
};

const Evp& LoadEvp() {
  static std::once_flag once;
  static Evp evp;
  static std::string error;
  std::call_once(once, [] {
    void* lib = ::dlopen(HANDDB_LIBCRYPTO_SONAME, RTLD_NOW | RTLD_LOCAL);
    if (lib == nullptr) {
      error = ::dlerror();
      return;
    }
    Evp e;
    e.ctx_new = reinterpret_cast<decltype(e.ctx_new)>(::dlsym(lib, "EVP_MD_CTX_new"));
    e.ctx_free = reinterpret_cast<decltype(e.ctx_free)>(::dlsym(lib, "EVP_MD_CTX_free"));
    e.sha256 = reinterpret_cast<decltype(e.sha256)>(::dlsym(lib, "EVP_sha256"));
    e.init = reinterpret_cast<decltype(e.init)>(::dlsym(lib, "EVP_DigestInit_ex"));
    e.update = reinterpret_cast<decltype(e.update)>(::dlsym(lib, "EVP_DigestUpdate"));
    e.final_ex = reinterpret_cast<decltype(e.final_ex)>(::dlsym(lib, "EVP_DigestFinal_ex"));
    if (e.ctx_new == nullptr || e.ctx_free == nullptr || e.sha256 == nullptr || e.init == nullptr ||
        e.update == nullptr || e.final_ex == nullptr) {
      error = std::string(HANDDB_LIBCRYPTO_SONAME) + " lacks the EVP digest functions";
      return;
    }
    evp = e;
  });
  THROW_CHECK_MSG(evp.ctx_new != nullptr, "SHA-256 needs OpenSSL's libcrypto: " << error);
  return evp;
}

}  // namespace

void Sha256::FreeContext::operator()(evp_md_ctx_st* ctx) const { LoadEvp().ctx_free(ctx); }

Sha256::Sha256() : ctx_(LoadEvp().ctx_new()) {
  const Evp& evp = LoadEvp();
  THROW_CHECK_MSG(ctx_ != nullptr, "EVP_MD_CTX_new failed");
  THROW_CHECK_MSG(evp.init(ctx_.get(), evp.sha256(), nullptr) == 1,
                  "EVP_DigestInit_ex(sha256) failed");
}

Sha256::~Sha256() = default;

void Sha256::Update(const void* data, size_t size) {
  THROW_CHECK_MSG(LoadEvp().update(ctx_.get(), data, size) == 1, "EVP_DigestUpdate failed");
}

std::string Sha256::HexDigest() {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int size = 0;
  THROW_CHECK_MSG(LoadEvp().final_ex(ctx_.get(), digest, &size) == 1, "EVP_DigestFinal_ex failed");
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
