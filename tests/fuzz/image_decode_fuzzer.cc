// libFuzzer target for the picture decoder (scripts/fuzz.sh): the bytes as a PNG or JPEG through
// DecodeImage in every mode cv::imread is asked for (unchanged, grey, colour, colour at 1/8), with
// the pixel bound lowered so a lying header cannot make one input allocate gigabytes.
#include <cstdint>
#include <span>

#include "base/image_decode.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using Mode = handdb::DecodeOptions::Mode;
  const std::span<const uint8_t> bytes(data, size);
  for (const handdb::DecodeOptions& base : {handdb::DecodeOptions{Mode::kUnchanged, 1},
                                            handdb::DecodeOptions{Mode::kGrey, 1},
                                            handdb::DecodeOptions{Mode::kColor, 1},
                                            handdb::DecodeOptions{Mode::kColor, 8}}) {
    handdb::DecodeOptions options = base;
    options.max_pixels = uint64_t{1} << 22;
    (void)handdb::DecodeImage(bytes, "fuzz", options);
  }
  return 0;
}
