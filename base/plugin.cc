#include "base/plugin.h"

#include <dlfcn.h>
#include <link.h>

#include <cstdlib>

namespace handdb {
namespace {

namespace fs = std::filesystem;

// The directory of the shared object (or executable) holding this function.
fs::path PluginLoaderDir() {
  Dl_info info{};
  if (::dladdr(reinterpret_cast<void*>(&PluginLoaderDir), &info) != 0 &&
      info.dli_fname != nullptr) {
    std::error_code ec;
    const fs::path p = fs::canonical(info.dli_fname, ec);
    if (!ec) return p.parent_path();
  }
  return {};
}

}  // namespace

std::vector<fs::path> PluginCandidates(const std::string& file_name, const char* env_var) {
  if (const char* env = std::getenv(env_var); env != nullptr && *env != '\0') {
    return {fs::path(env)};
  }
  std::vector<fs::path> out;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    out.push_back(exe.parent_path() / file_name);
    out.push_back(exe.parent_path().parent_path() / "lib" / "handdb" / file_name);
  }
  if (const fs::path here = PluginLoaderDir(); !here.empty()) out.push_back(here / file_name);
  out.push_back(fs::path(HANDDB_PLUGIN_BUILD_DIR) / file_name);
  return out;
}

Result<void*> OpenPlugin(const std::string& file_name,
                         const char* env_var,
                         const std::string& what) {
  std::string tried;
  for (const fs::path& candidate : PluginCandidates(file_name, env_var)) {
    std::error_code ec;
    if (!fs::exists(candidate, ec)) {
      tried += (tried.empty() ? "" : ", ") + candidate.string();
      continue;
    }
    void* lib = ::dlopen(candidate.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (lib == nullptr) {
      return Status(StatusCode::kIoError,
                    what + ": " + candidate.string() + " cannot be loaded: " + ::dlerror());
    }
    return lib;
  }
  return Status(StatusCode::kNotFound,
                what + " needs the plugin " + file_name + ", which is not installed (looked in " +
                    tried + "; set " + env_var + ")");
}

std::string PluginFile(void* handle, const std::string& file_name) {
  link_map* map = nullptr;
  if (::dlinfo(handle, RTLD_DI_LINKMAP, &map) == 0 && map != nullptr && map->l_name != nullptr &&
      *map->l_name != '\0') {
    return map->l_name;
  }
  return file_name;
}

}  // namespace handdb
