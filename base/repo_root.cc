#include "base/repo_root.h"

#include <cstdlib>

#include "handdb_version.h"

namespace handdb {

std::filesystem::path RepoRoot() {
  if (const char* env = std::getenv("HANDDB_SOURCE_DIR"); env != nullptr && *env != '\0')
    return env;
  return HANDDB_SOURCE_DIR;
}

}  // namespace handdb
