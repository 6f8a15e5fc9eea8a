#include "base/hex.h"

namespace handdb {
namespace {

constexpr char kDigits[] = "0123456789abcdef";

}  // namespace

std::string HexPrefixed(uint64_t v) {
  std::string digits;
  do {
    digits.insert(digits.begin(), kDigits[v & 0xf]);
    v >>= 4;
  } while (v != 0);
  return "0x" + digits;
}

std::string Hex64(uint64_t v) {
  std::string out(16, '0');
  for (int i = 15; i >= 0; --i, v >>= 4) out[static_cast<size_t>(i)] = kDigits[v & 0xf];
  return out;
}

std::string HexBytes(const void* data, size_t size, std::string_view separator) {
  const auto* p = static_cast<const uint8_t*>(data);
  std::string out;
  out.reserve(size * (2 + separator.size()));
  for (size_t i = 0; i < size; ++i) {
    if (i != 0) out += separator;
    out += kDigits[p[i] >> 4];
    out += kDigits[p[i] & 0xf];
  }
  return out;
}

}  // namespace handdb
