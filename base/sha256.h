// SHA-256 (FIPS 180-4, computed by Nettle: the digests of GnuTLS, a library of ~700 relocations
// where OpenSSL's libcrypto has ~21,000, so linking it costs a command's start nothing measurable;
// docs/decisions/0022), for recording which hand-model and asset files a plan, a database and its
// rig were made from.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "base/status.h"

// Nettle's context (nettle/sha2.h), declared so the header needs no Nettle include.
struct sha256_ctx;

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
  std::unique_ptr<sha256_ctx> ctx_;
};

std::string Sha256Hex(std::string_view data);
// kNotFound / kIoError name the path.
Result<std::string> Sha256File(const std::filesystem::path& path);

}  // namespace handdb
