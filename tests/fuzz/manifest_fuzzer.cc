// libFuzzer target for the manifest reader (scripts/fuzz.sh): the bytes as DB/manifest.json
// through ReadManifest (ReadJsonFile's bounds and schema, then ManifestFromJson's consistency
// checks), and a valid manifest back through JSON.
#include <cstdint>
#include <cstdlib>

#include "format/manifest.h"
#include "fuzz_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = handdb::fuzz::WriteInput(data, size, "manifest.json");
  auto manifest = handdb::ReadManifest(path.parent_path());
  if (manifest.ok()) {
    // What we accept we can write and read again.
    auto again = handdb::ManifestFromJson(handdb::ManifestToJson(*manifest), "round trip");
    if (!again.ok()) std::abort();
  }
  return 0;
}
