// Helpers for unit tests only (header-only; no library links it): fresh temporary directories and
// whole-file byte reads and writes.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "base/atomic_file.h"
#include "base/status.h"

namespace handdb::testing {

// An empty directory <tmp>/handdb_test_<name>_<pid>, removed first if an earlier run left it.
inline std::filesystem::path TempDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("handdb_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// The whole file; throws (fails the test) if it cannot be read.
inline std::vector<uint8_t> ReadBytes(const std::filesystem::path& path) {
  auto s = ReadFileToString(path);
  THROW_CHECK_MSG(s.ok(), s.status().ToString());
  return std::vector<uint8_t>(s->begin(), s->end());
}

// Replaces the file atomically; throws (fails the test) on error.
inline void WriteBytes(const std::filesystem::path& path, const std::vector<uint8_t>& bytes) {
  const Status s = WriteFileAtomic(
      path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  THROW_CHECK_MSG(s.ok(), s.ToString());
}

}  // namespace handdb::testing
