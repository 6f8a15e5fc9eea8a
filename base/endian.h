// Little-endian loads and stores of fixed-width values at any (unaligned) address: the byte order
// of every binary file handdb writes or reads (shards, the search index, image headers). The
// on-disk structs build their codecs on these (RawHeader::EncodeTo / DecodeFrom, after LevelDB's
// BlockHandle); on a little-endian host each is one unaligned move.
#pragma once

#include <algorithm>
#include <bit>
#include <cstring>
#include <type_traits>

namespace handdb {

template <typename T>
inline T LoadLittleEndian(const void* p) {
  static_assert(std::is_trivially_copyable_v<T>);
  unsigned char bytes[sizeof(T)];
  std::memcpy(bytes, p, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + sizeof(T));
  T v;
  std::memcpy(&v, bytes, sizeof(T));
  return v;
}

template <typename T>
inline void StoreLittleEndian(void* p, T v) {
  static_assert(std::is_trivially_copyable_v<T>);
  unsigned char bytes[sizeof(T)];
  std::memcpy(bytes, &v, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + sizeof(T));
  std::memcpy(p, bytes, sizeof(T));
}

}  // namespace handdb
