// Deterministic synthetic views and small sample shards for the format tests, the fuzz seed
// corpus and bench/format_bench.cc. Labels are self-consistent (unit view direction, matching
// theta/phi, scale * source diameter = 192 px) so the validator accepts them.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "base/status.h"
#include "format/shard_layout.h"
#include "format/shard_writer.h"
#include "format/view.h"

namespace handdb::testing {

inline uint64_t SplitMix(uint64_t* state) {
  uint64_t z = (*state += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

inline float Uniform(uint64_t* state, float lo, float hi) {
  return lo + (hi - lo) * static_cast<float>(SplitMix(state) >> 40) / static_cast<float>(1 << 24);
}

inline ViewLabel SyntheticLabel(uint32_t i) {
  uint64_t s = 0x1234 + i;
  ViewLabel l;
  l.render_id = i;
  l.shape_id = i / 86;
  l.dir_id = i % 86;
  for (auto& a : l.joint_angles) a = Uniform(&s, 0.0f, 1.2f);
  const float theta = Uniform(&s, 0.1f, 3.0f);
  const float phi = Uniform(&s, -3.0f, 3.0f);
  l.view_direction = {
      std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
  l.view_theta = std::acos(l.view_direction[2]);
  l.view_phi = std::atan2(l.view_direction[1], l.view_direction[0]);
  l.camera_roll = 0;
  for (auto& kp : l.keypoints)
    kp = {Uniform(&s, -90, 90), Uniform(&s, -90, 90), Uniform(&s, -50, 50)};
  l.source_diameter_px = Uniform(&s, 100, 200);
  l.scale = kNormalisedDiameter / l.source_diameter_px;
  l.source_centre_px = {Uniform(&s, 100, 150), Uniform(&s, 100, 150)};
  return l;
}

// n points on a noisy closed contour of radius ~96 px, in 1/16 px.
inline std::vector<PointQ> SyntheticPoints(uint32_t i, size_t n) {
  uint64_t s = 0xabcd + i;
  std::vector<PointQ> pts(n);
  for (size_t k = 0; k < n; ++k) {
    const float t = 6.2831853f * static_cast<float>(k) / static_cast<float>(n);
    const float r = 96.0f + Uniform(&s, -20, 20);
    pts[k] = {static_cast<int16_t>(std::lround(r * std::cos(t) * kPointScale)),
              static_cast<int16_t>(std::lround(r * std::sin(t) * kPointScale))};
  }
  return pts;
}

// Points as the converter makes them from a render (edges/normalise.cc): the pixels of a noisy
// closed contour in the label's source image, normalised in double with the label's scale and
// centre, unique and sorted by (y, x), so a coded shard stores them with the lattice code.
inline std::vector<PointQ> LatticePoints(const ViewLabel& label, uint32_t i) {
  uint64_t s = 0x5eed + i;
  const double radius_px = 0.5 * label.source_diameter_px;
  std::vector<std::pair<int, int>> pixels;  // (row, col)
  const int n = 400;
  for (int k = 0; k < n; ++k) {
    const double t = 6.283185307179586 * k / n;
    const double r = radius_px * (0.8 + 0.2 * std::sin(5 * t)) + Uniform(&s, -0.7f, 0.7f);
    pixels.emplace_back(static_cast<int>(label.source_centre_px[1] + r * std::sin(t)),
                        static_cast<int>(label.source_centre_px[0] + r * std::cos(t)));
  }
  std::sort(pixels.begin(), pixels.end());
  pixels.erase(std::unique(pixels.begin(), pixels.end()), pixels.end());
  std::vector<PointQ> out;
  for (const auto& [row, col] : pixels) {
    out.push_back(
        {static_cast<int16_t>(std::nearbyint((col + 0.5 - label.source_centre_px[0]) *
                                             static_cast<double>(label.scale) * kPointScale)),
         static_cast<int16_t>(std::nearbyint((row + 0.5 - label.source_centre_px[1]) *
                                             static_cast<double>(label.scale) * kPointScale))});
  }
  return out;  // rows ascending, columns ascending within a row: sorted by (y, x)
}

// 20 joint limits [0, 1.6] rad in the metadata JSON, as the converter writes them.
inline std::string SyntheticMetadata() {
  std::string limits;
  for (int j = 0; j < kNumJointAngles; ++j) limits += std::string(j ? "," : "") + "[-0.5,1.6]";
  return R"({"tool_version":"test","hand_model":{"name":"synthetic","sha256":")" +
         std::string(64, '0') + R"(","joint_limits":[)" + limits + "]}}";
}

// n points uniform in [-spread_units, spread_units]^2 (1/16 px).
inline std::vector<PointQ> RandomPoints(std::mt19937* rng, size_t n, int spread_units) {
  std::uniform_int_distribution<int> u(-spread_units, spread_units);
  std::vector<PointQ> pts;
  for (size_t i = 0; i < n; ++i) {
    pts.push_back({static_cast<int16_t>(u(*rng)), static_cast<int16_t>(u(*rng))});
  }
  return pts;
}

// Writes a shard of `num_views` views with 5 + (i % 7) * points_scale points each.
inline Result<ShardSummary> WriteSyntheticShard(const std::filesystem::path& path,
                                                uint32_t num_views,
                                                size_t points_per_view = 0,
                                                ShardWriterOptions options = {}) {
  if (options.metadata_json == "{}") options.metadata_json = SyntheticMetadata();
  ShardWriter writer;
  HANDDB_RETURN_IF_ERROR(writer.Open(path, options));
  for (uint32_t i = 0; i < num_views; ++i) {
    const size_t n = points_per_view ? points_per_view : 5 + (i % 7);
    HANDDB_RETURN_IF_ERROR(writer.AddView(SyntheticLabel(i), SyntheticPoints(i, n)));
  }
  return writer.Finish();
}

// Damages view 0's point code in a coded shard's bytes: 20 bytes of its chains, past the mode,
// lengths, count and box its open reads, set to 0xff; then the checksums are rewritten, so only
// decoding the view finds the damage.
inline void DamageFirstPointCode(std::vector<uint8_t>* bytes) {
  const shard::RawHeader h = shard::RawHeader::DecodeFrom(*bytes);
  for (uint32_t i = 0; i < h.section_count; ++i) {
    const shard::RawSection sec = shard::RawSection::DecodeFrom(
        bytes->data() + h.section_table_offset + i * h.section_entry_size);
    if (sec.type == shard::kSectionPointCodes) {
      for (size_t k = 20; k < 40; ++k) (*bytes)[sec.offset + k] = 0xff;
    }
  }
  THROW_CHECK(shard::RewriteChecksums(*bytes));
}

}  // namespace handdb::testing
