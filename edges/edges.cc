#include "edges/edges.h"

#include <cmath>

namespace handdb {

void JointPairs::Add(int a, int b) {
  THROW_CHECK(a >= 1 && a <= kNumLinks);
  THROW_CHECK(b >= 1 && b <= kNumLinks);
  THROW_CHECK_NE(a, b);
  if (!table_[a][b]) ++count_;
  table_[a][b] = true;
  table_[b][a] = true;
}

JointPairs DefaultJointPairs() {
  JointPairs pairs;
  constexpr int kPalm = 1;
  for (int first : {2, 5, 8, 11, 14}) {
    pairs.Add(kPalm, first);
    pairs.Add(first, first + 1);
    pairs.Add(first + 1, first + 2);
  }
  return pairs;
}

bool EdgeOptions::Check() const {
  CHECK_OPTION(std::isfinite(depth_jump));
  CHECK_OPTION_GT(depth_jump, 0.0);
  return true;
}

nlohmann::json EdgeOptions::ToJson() const {
  return {{"rule",
           "4-neighbour label change; joint pairs dropped unless occlusion; silhouette always; "
           "the nearer pixel of a border is the edge pixel; points at pixel centres"},
          {"occlusion_edges", occlusion_edges},
          {"depth_jump", depth_jump},
          {"depth_jump_unit", "scene units of the Depth pass"}};
}

Result<EdgeOptions> EdgeOptions::FromJson(const nlohmann::json& doc, const std::string& what) {
  auto bad = [&](const std::string& problem) {
    return Status(StatusCode::kBadJson, what + ": " + problem);
  };
  if (!doc.is_object()) return bad("not an object");
  EdgeOptions options;
  const auto occlusion = doc.find("occlusion_edges");
  if (occlusion == doc.end() || !occlusion->is_boolean()) {
    return bad("occlusion_edges missing or not a boolean");
  }
  options.occlusion_edges = occlusion->get<bool>();
  const auto jump = doc.find("depth_jump");
  if (jump == doc.end() || !jump->is_number()) return bad("depth_jump missing or not a number");
  options.depth_jump = jump->get<double>();
  if (!options.Check()) return bad("depth_jump must be finite and positive");
  return options;
}

EdgeResult ExtractEdges(const LabelImage& image,
                        const JointPairs& joint_pairs,
                        const EdgeOptions& options) {
  const int w = image.width;
  const int h = image.height;
  THROW_CHECK(w >= 0 && h >= 0);
  const size_t n = static_cast<size_t>(w) * static_cast<size_t>(h);
  THROW_CHECK_EQ(image.labels.size(), n);
  THROW_CHECK(image.depth.empty() || image.depth.size() == n);
  const bool use_depth = options.occlusion_edges && image.has_depth();
  const uint8_t* lab = image.labels.data();
  const float* depth = image.depth.data();
  for (size_t i = 0; i < n; ++i) THROW_CHECK_LE(static_cast<int>(lab[i]), kNumLinks);

  // Bit 1: edge pixel; bit 2: silhouette pixel.
  constexpr uint8_t kEdge = 1;
  constexpr uint8_t kSilhouette = 2;
  std::vector<uint8_t> mask(n, 0);
  EdgeResult result;

  // Marks the border between pixels i and j (4-adjacent, labels differ).
  auto border = [&](size_t i, size_t j) {
    const int a = lab[i];
    const int b = lab[j];
    if (a == 0 || b == 0) {
      const size_t hand = a == 0 ? j : i;
      mask[hand] |= kEdge | kSilhouette;
      return;
    }
    if (joint_pairs.Contains(a, b)) {
      if (!use_depth) return;
      if (!(std::fabs(depth[i] - depth[j]) > options.depth_jump)) return;
    }
    // The nearer pixel carries the edge: it belongs to the occluding surface. Ties (and unknown
    // depth) go to the first pixel in raster order.
    const bool j_nearer = image.has_depth() && depth[j] < depth[i];
    mask[j_nearer ? j : i] |= kEdge;
  };

  for (int row = 0; row < h; ++row) {
    const size_t base = static_cast<size_t>(row) * w;
    for (int col = 0; col < w; ++col) {
      const size_t i = base + col;
      const int a = lab[i];
      if (a != 0) {
        ++result.num_hand_pixels;
        if (row == 0 || col == 0 || row == h - 1 || col == w - 1) {
          result.touches_border = true;
          // Outside the image counts as background: keeps the contour closed.
          mask[i] |= kEdge | kSilhouette;
        }
      }
      if (col + 1 < w && lab[i + 1] != a) border(i, i + 1);
      if (row + 1 < h && lab[i + w] != a) border(i, i + w);
    }
  }

  for (int row = 0; row < h; ++row) {
    const size_t base = static_cast<size_t>(row) * w;
    for (int col = 0; col < w; ++col) {
      const uint8_t m = mask[base + col];
      if (m & kEdge) result.edges.push_back({col, row});
      if (m & kSilhouette) result.silhouette.push_back({col, row});
    }
  }
  return result;
}

}  // namespace handdb
