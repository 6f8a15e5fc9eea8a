// libFuzzer target for the label EXR reader (scripts/fuzz.sh): the bytes as a render's
// r000123.exr through ReadLabelExr (OpenEXR's header and pixel decoding, then the label and depth
// checks). Seeds (corpus/exr): 8x6 label images written by WriteLabelExr as float without
// compression, float zip, half zip with Blender's Combined pass, and without depth.
#include <cmath>
#include <cstdint>
#include <cstdlib>

#include "edges/exr_io.h"
#include "fuzz_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = handdb::fuzz::WriteInput(data, size, "r000123.exr");
  handdb::ExrReadOptions options;
  options.require_depth = false;
  auto image = handdb::ReadLabelExr(path, options);
  if (image.ok()) {
    // What is accepted is what the converter relies on: a sized image, labels in 0..16, depth
    // (if any) of the same size and finite on the hand.
    const size_t n = static_cast<size_t>(image->width) * static_cast<size_t>(image->height);
    if (image->width <= 0 || image->height <= 0 || image->labels.size() != n) std::abort();
    if (!image->depth.empty() && image->depth.size() != n) std::abort();
    for (size_t i = 0; i < n; ++i) {
      if (image->labels[i] > handdb::kNumLinks) std::abort();
      if (!image->depth.empty() && image->labels[i] != 0 && !std::isfinite(image->depth[i])) {
        std::abort();
      }
    }
  }
  return 0;
}
