// write_test_database DIR [--shapes N] [--directions N] [--rolls R] [--shards N] [--points N]
//                     [--coded 1]
//
// A small database without Blender for the install and Python tests: hand-like
// synthetic views (query/search_testing.h: a palm outline and five fingers per shape, foreshortened
// and turned per direction), self-consistent labels, shape names in the manifest, split over
// --shards shards (coded shards, format v1.2, with --coded 1). Deterministic: the same arguments
// give byte-identical files.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "format/manifest.h"
#include "format/shard_writer.h"
#include "query/search_testing.h"

namespace {

namespace fs = std::filesystem;

int Usage() {
  std::fprintf(stderr,
               "usage: write_test_database DIR [--shapes N] [--directions N] [--rolls R] "
               "[--shards N] [--points N] [--coded 1]\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace handdb;
  if (argc < 2) return Usage();
  const fs::path dir = argv[1];
  uint32_t shapes = 4, directions = 12, rolls = 12, shards = 2, points = 300;
  ShardWriterOptions options;
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    const auto value = static_cast<uint32_t>(std::strtoul(argv[i + 1], nullptr, 10));
    if (value == 0) return Usage();
    if (flag == "--shapes") {
      shapes = value;
    } else if (flag == "--directions") {
      directions = value;
    } else if (flag == "--rolls") {
      rolls = value;
    } else if (flag == "--shards") {
      shards = value;
    } else if (flag == "--points") {
      points = value;
    } else if (flag == "--coded") {
      options.coded = true;
    } else {
      return Usage();
    }
  }
  if (argc % 2 != 0) return Usage();
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) {
    std::fprintf(stderr, "write_test_database: %s: %s\n", dir.c_str(), ec.message().c_str());
    return 1;
  }
  const char* kNames[] = {"fist", "flat", "point", "pinch", "spread", "thumbs-up"};
  Manifest manifest;
  manifest.tool_version = "write_test_database";
  manifest.rolls = rolls;
  manifest.metadata["shapes"] = nlohmann::json::array();
  for (uint32_t s = 0; s < shapes; ++s) {
    const std::string name = s < 6 ? kNames[s] : "shape-" + std::to_string(s);
    manifest.metadata["shapes"].push_back({{"id", s}, {"name", name}});
  }
  const uint32_t num_views = shapes * directions;
  const uint32_t per_shard = (num_views + shards - 1) / shards;
  for (uint32_t first = 0, unit = 0; first < num_views; first += per_shard, ++unit) {
    char file[32];
    std::snprintf(file, sizeof(file), "shard-%05u.hdb", unit);
    ShardWriter writer;
    Status st = writer.Open(dir / file, options);
    for (uint32_t v = first; st.ok() && v < std::min(num_views, first + per_shard); ++v) {
      st = writer.AddView(
          testing::SyntheticViewLabel(v, directions),
          testing::SyntheticHandEdges(v / directions, v % directions, directions, points));
    }
    if (!st.ok()) {
      std::fprintf(stderr, "write_test_database: %s\n", st.message().c_str());
      return 1;
    }
    auto summary = writer.Finish();
    if (!summary.ok()) {
      std::fprintf(stderr, "write_test_database: %s\n", summary.status().message().c_str());
      return 1;
    }
    manifest.AddShard(*summary);
  }
  const Status st = WriteManifest(dir, manifest);
  if (!st.ok()) {
    std::fprintf(stderr, "write_test_database: %s\n", st.message().c_str());
    return 1;
  }
  std::printf("%s: %u views x %u rolls in %zu shards\n",
              dir.c_str(),
              num_views,
              rolls,
              manifest.shards.size());
  return 0;
}
