// libFuzzer target for the config readers (scripts/fuzz.sh): the bytes as a generation config and
// as a test-set config, through ReadJsonFile (regular file, size and depth bounds, parse, schema).
// MakePlan is left out: a schema-valid config can ask for a huge plan (kMaxPlanRenders).
#include <cstdint>

#include "base/json_schema.h"
#include "fuzz_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = handdb::fuzz::WriteInput(data, size, "config.json");
  (void)handdb::ReadJsonFile(path, "config.schema.json");
  (void)handdb::ReadJsonFile(path, "testset_config.schema.json");
  return 0;
}
