// Edge pixels of a rendered link-label image (docs/conversion.md "Edge rule").
//
// A border between two 4-adjacent pixels with different labels is an edge, except a border
// between a joint pair (parent and child link, e.g. palm and index link 1) whose depths are
// continuous. The silhouette (hand vs background) is always an edge. With occlusion edges on, a
// joint-pair border across a depth jump larger than `depth_jump` (a finger folded over its own
// palm) is kept as an occlusion edge.
//
// Each edge border marks ONE pixel: the nearer of the two (smaller depth; the hand side of the
// silhouette), so edges are one pixel thick and belong to the occluding surface. Edge points are
// the centres of the marked pixels: (col + 0.5, row + 0.5) in rendered pixels.
#pragma once

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/view.h"

namespace handdb {

// A rendered view: per-pixel link ids (0 = background, 1..16) and optional depth (camera-space
// distance along the view axis, scene units; empty = unknown). Row-major, row 0 at the top.
struct LabelImage {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> labels;
  std::vector<float> depth;  // width*height values, or empty

  uint8_t label(int col, int row) const { return labels[static_cast<size_t>(row) * width + col]; }
  bool has_depth() const { return !depth.empty(); }
};

// Symmetric table of link pairs joined by a joint (hand model), indexed by link id 0..16.
class JointPairs {
 public:
  JointPairs() { table_.fill({}); }
  void Add(int a, int b);  // THROW_CHECK on ids outside 1..kNumLinks
  bool Contains(int a, int b) const { return table_[a][b]; }
  int size() const { return count_; }

 private:
  std::array<std::array<bool, kNumLinks + 1>, kNumLinks + 1> table_;
  int count_ = 0;
};

// The 15 parent/child pairs of the hand model (docs/conversion.md "Edge rule"): palm 1; thumb 2-4;
// index 5-7; middle 8-10; ring 11-13; pinky 14-16; each finger chain (1, f), (f, f+1), (f+1, f+2).
JointPairs DefaultJointPairs();

// The defaults (on, 10 mm) were chosen by evaluation on the paper database and test set: occlusion
// edges make photo queries better than no occlusion edges and tie on clean labels; 10 mm ranked
// photo queries best of 5, 10 and 20 mm (docs/conversion.md, "Choosing the occlusion-edge
// default").
struct EdgeOptions {
  // Keep joint-pair borders across a depth jump as occlusion edges.
  bool occlusion_edges = true;
  // Depth difference (scene units of the Depth pass, metres for the shipped hand) above which a
  // joint-pair border is an occlusion edge.
  double depth_jump = 0.010;
  bool Check() const;

  // The options as a database records them (the manifest's and each shard's `conversion.edges`,
  // which add the hand's joint_pairs): occlusion_edges, depth_jump, the rule in words and the
  // depth unit.
  nlohmann::json ToJson() const;
  // The inverse; other fields are ignored. kBadJson ("WHAT: not an object", "WHAT: depth_jump
  // missing or not a number", ...) when a field is missing, mistyped or fails Check().
  static Result<EdgeOptions> FromJson(const nlohmann::json& doc, const std::string& what);
};

// Pixels (col, row) of the marked edge pixels, in raster order.
struct EdgePixel {
  int32_t col;
  int32_t row;
};

struct EdgeResult {
  std::vector<EdgePixel> edges;       // every edge pixel (silhouette + internal), raster order
  std::vector<EdgePixel> silhouette;  // hand pixels with a background 4-neighbour, raster order
  int64_t num_hand_pixels = 0;
  bool touches_border = false;  // a hand pixel lies on the outermost row or column
};

// `image.labels` must hold values 0..kNumLinks (THROW_CHECK: validate input first, e.g. with
// ReadLabelExr). Joint-pair borders with unknown depth are dropped.
EdgeResult ExtractEdges(const LabelImage& image,
                        const JointPairs& joint_pairs,
                        const EdgeOptions& options);

}  // namespace handdb
