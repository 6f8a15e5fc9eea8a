#include "base/repo_root.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>
#include <string>

#include "handdb_version.h"

namespace handdb {
namespace {

// Sets HANDDB_SOURCE_DIR for one test and puts back what was there.
class SourceDirEnv {
 public:
  explicit SourceDirEnv(const char* value) {
    if (const char* old = std::getenv("HANDDB_SOURCE_DIR")) old_ = old;
    if (value) {
      setenv("HANDDB_SOURCE_DIR", value, 1);
    } else {
      unsetenv("HANDDB_SOURCE_DIR");
    }
  }
  ~SourceDirEnv() {
    if (old_) {
      setenv("HANDDB_SOURCE_DIR", old_->c_str(), 1);
    } else {
      unsetenv("HANDDB_SOURCE_DIR");
    }
  }

 private:
  std::optional<std::string> old_;
};

TEST(RepoRoot, EnvironmentOverridesTheBuildsSourceDir) {
  SourceDirEnv env("/somewhere/else");
  EXPECT_EQ(RepoRoot(), std::filesystem::path("/somewhere/else"));
}

TEST(RepoRoot, UnsetOrEmptyMeansTheBuildsSourceDir) {
  {
    SourceDirEnv env(nullptr);
    EXPECT_EQ(RepoRoot(), std::filesystem::path(HANDDB_SOURCE_DIR));
  }
  SourceDirEnv env("");
  EXPECT_EQ(RepoRoot(), std::filesystem::path(HANDDB_SOURCE_DIR));
  EXPECT_TRUE(std::filesystem::exists(RepoRoot() / "configs" / "paper.json"));
}

}  // namespace
}  // namespace handdb
