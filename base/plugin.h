// Shared objects of handdb that a process opens (dlopen) on first use instead of linking, so a
// command that does not need their libraries never loads them (docs/decisions/0020): the pose
// fit's solver (libhanddb_fit.so, pose/fit.h) and PCL's kd-tree backend
// (libhanddb_pcl_kdtree.so, query/kdtree.h). They are installed beside the handdb binary and
// beside the Python module, and built beside the binary.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "base/status.h"

namespace handdb {

// Where a plugin is looked for: $`env_var` alone when set; else, in order, beside the running
// executable, in its ../lib/handdb, beside the shared object holding this code (the Python
// module), then the build tree's directory of plugins.
std::vector<std::filesystem::path> PluginCandidates(const std::string& file_name,
                                                    const char* env_var);

// dlopen (RTLD_NOW | RTLD_LOCAL) of the first candidate that exists; the handle is never closed.
// kNotFound: "<what> needs the plugin <file_name>, which is not installed (looked in ...; set
// <env_var>)"; kIoError: a candidate that exists but cannot be loaded, with dlerror's words.
Result<void*> OpenPlugin(const std::string& file_name,
                         const char* env_var,
                         const std::string& what);

// The file a handle of OpenPlugin was loaded from, for a message about it (`file_name` when the
// loader cannot say).
std::string PluginFile(void* handle, const std::string& file_name);

}  // namespace handdb
