// libFuzzer target for the point and field codes (format/point_codec.h, format/field_codec.h;
// scripts/fuzz.sh). The first byte picks the decoder (mod 3): 0 lattice pixels, 1 a view's
// points (the next 12 bytes are three floats: the scale, the centre's x and y), 2 a coarse field;
// the rest is the code. What a decoder accepts must survive its encoder: the
// re-encoded code decodes to the same pixels, points or field; and a view code's header
// (PeekViewPoints) must agree with what the code decodes to (count, bound, order).
#include <array>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "format/field_codec.h"
#include "format/point_codec.h"

namespace {

std::span<const uint8_t> Bytes(const std::string& s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

bool Same(const std::vector<handdb::PointQ>& a, const std::vector<handdb::PointQ>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].x != b[i].x || a[i].y != b[i].y) return false;
  }
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::span<const uint8_t> input(data + 1, size - 1);
  switch (data[0] % 3) {
    case 0: {
      std::vector<handdb::LatticePixel> pixels, again;
      if (!handdb::DecodeLatticePixels(input, &pixels).ok()) return 0;
      std::string code;
      if (!handdb::EncodeLatticePixels(pixels, &code).ok()) std::abort();
      if (!handdb::DecodeLatticePixels(Bytes(code), &again).ok() || again != pixels) std::abort();
      return 0;
    }
    case 1: {
      if (input.size() < 12) return 0;
      float scale = 0;
      std::array<float, 2> centre{};
      std::memcpy(&scale, input.data(), 4);
      std::memcpy(centre.data(), input.data() + 4, 8);
      std::vector<handdb::PointQ> points, again;
      handdb::ViewPointsExtent extent;
      const bool peek_ok = handdb::PeekViewPoints(input.subspan(12), scale, centre, &extent).ok();
      const bool peeked = peek_ok && extent.peeked;
      if (!handdb::DecodeViewPoints(input.subspan(12), scale, centre, &points).ok()) return 0;
      if (!peek_ok) std::abort();  // a header the peek refuses, on a code that decodes
      // What the header promised (the query's Database relies on it without decoding).
      if (peeked) {
        if (extent.count != points.size()) std::abort();
        for (size_t i = 0; i < points.size(); ++i) {
          if (std::abs(static_cast<int32_t>(points[i].x)) > extent.max_abs_bound ||
              std::abs(static_cast<int32_t>(points[i].y)) > extent.max_abs_bound ||
              (i > 0 && points[i - 1].y > points[i].y)) {
            std::abort();
          }
        }
      }
      std::string code;
      if (!handdb::EncodeViewPoints(points, scale, centre, &code).ok()) std::abort();
      if (!handdb::DecodeViewPoints(Bytes(code), scale, centre, &again).ok() ||
          !Same(points, again)) {
        std::abort();
      }
      return 0;
    }
    default: {
      std::array<uint8_t, handdb::CoarseGrid::kCells> field{}, again{};
      if (!handdb::DecodeCoarseField(input, field).ok()) return 0;
      std::string code;
      handdb::EncodeCoarseField(field, &code);
      if (!handdb::DecodeCoarseField(Bytes(code), again).ok() || again != field) std::abort();
      return 0;
    }
  }
}
