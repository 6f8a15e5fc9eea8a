// The source tree handdb reads its data from at run time (configs/, blender_scripts/ and the
// assets scripts/deps.sh installs under third_party/assets/).
#pragma once

#include <filesystem>

namespace handdb {

// $HANDDB_SOURCE_DIR if set and not empty, else the source directory this binary was built from.
std::filesystem::path RepoRoot();

}  // namespace handdb
