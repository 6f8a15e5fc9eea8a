// The JSON readers' fuzz targets go through the real path-taking readers (size and regular-file
// checks, depth bound, parse, schema, the struct's own checks), so each input is written to a file
// in a per-process temporary directory first.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

namespace handdb::fuzz {

// <tmp>/handdb-fuzz-<pid>/<name>, holding exactly `data`.
inline std::filesystem::path WriteInput(const uint8_t* data, size_t size, const char* name) {
  static const std::filesystem::path dir = [] {
    auto d = std::filesystem::temp_directory_path() / ("handdb-fuzz-" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    return d;
  }();
  const std::filesystem::path path = dir / name;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) std::abort();  // the fuzz run's own temp dir must be writable
  if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

}  // namespace handdb::fuzz
