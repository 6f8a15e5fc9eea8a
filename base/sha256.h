// SHA-256 (FIPS 180-4), for recording which hand-model and asset files a plan was made from.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "base/status.h"

namespace handdb {

class Sha256 {
 public:
  Sha256();
  void Update(const void* data, size_t size);
  void Update(std::string_view data) { Update(data.data(), data.size()); }
  std::string HexDigest();  // finalises; lower-case hex, 64 characters

 private:
  void Block(const uint8_t* p);
  uint32_t h_[8];
  uint8_t buf_[64];
  size_t buf_len_ = 0;
  uint64_t total_ = 0;
};

std::string Sha256Hex(std::string_view data);
// kNotFound / kIoError name the path.
Result<std::string> Sha256File(const std::filesystem::path& path);

}  // namespace handdb
