// libFuzzer target for the render sidecar reader (scripts/fuzz.sh): the bytes as a render's
// r000123.json through ReadSidecar (ReadJsonFile's bounds, then ParseSidecar's field checks).
// Seeds: a real sidecar of the paper database and a 70-deep array.
#include <cmath>
#include <cstdint>
#include <cstdlib>

#include "edges/view_conversion.h"
#include "fuzz_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = handdb::fuzz::WriteInput(data, size, "r000123.json");
  auto sidecar = handdb::ReadSidecar(path);
  if (sidecar.ok()) {
    // What is accepted is usable: a resolution the converter can size an image by.
    if (sidecar->resolution <= 0 || sidecar->resolution > 65536) std::abort();
  }
  return 0;
}
