// SHA-256 (FIPS 180-4, computed by OpenSSL's EVP, its library opened on the first digest), for
// recording which hand-model and asset files a plan was made from.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "base/status.h"

// OpenSSL's EVP_MD_CTX (openssl/types.h), declared so the header needs no OpenSSL include.
struct evp_md_ctx_st;

namespace handdb {

class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;

  void Update(const void* data, size_t size);
  void Update(std::string_view data) { Update(data.data(), data.size()); }
  std::string HexDigest();  // finalises; lower-case hex, 64 characters

 private:
  struct FreeContext {
    void operator()(evp_md_ctx_st* ctx) const;
  };
  std::unique_ptr<evp_md_ctx_st, FreeContext> ctx_;  // OpenSSL's EVP_MD_CTX
};

std::string Sha256Hex(std::string_view data);
// kNotFound / kIoError name the path.
Result<std::string> Sha256File(const std::filesystem::path& path);

}  // namespace handdb
