// Lower-case hexadecimal text, the one place the project formats hex (checksums, digests, flags
// and raw bytes in error messages).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace handdb {

// "0x" and the shortest digits: 0 -> "0x0", 255 -> "0xff" (flags and field values in messages).
std::string HexPrefixed(uint64_t v);
// Exactly 16 digits, zero-padded: the big-endian text of a 64-bit checksum (what xxhsum prints).
std::string Hex64(uint64_t v);
// Two digits per byte in memory order, `separator` between bytes: {0x68, 0x64}, " " -> "68 64".
std::string HexBytes(const void* data, size_t size, std::string_view separator = {});

}  // namespace handdb
