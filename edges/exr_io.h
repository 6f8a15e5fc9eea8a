// Reading the Blender multilayer EXRs the renderer writes (docs/conventions.md, "EXR channels"):
// the link-label channel is the one whose name ends in "IndexMA.X" (material pass index, exact
// integers 0..16), depth the one ending in "Depth.Z". Everything about the file is validated
// before a label image is returned, so a bad render never reaches a shard.
#pragma once

#include <filesystem>
#include <string>

#include "base/status.h"
#include "edges/edges.h"

namespace handdb {

inline constexpr const char* kLabelChannelSuffix = "IndexMA.X";
inline constexpr const char* kDepthChannelSuffix = "Depth.Z";

struct ExrReadOptions {
  int expected_width = 0;   // 0: any
  int expected_height = 0;  // 0: any
  bool require_depth = true;
  bool Check() const;
};

// Errors, each "<path>: <problem>":
//   kNotFound (no file), kBadImage (not an EXR / unreadable header / no label or depth channel),
//   kSizeMismatch (resolution or data window differs from the expected one), kTruncated (pixel
//   data cannot be read: truncated or corrupt), kOutOfRange (a label that is not an integer in
//   0..16, or non-finite depth on the hand).
Result<LabelImage> ReadLabelExr(const std::filesystem::path& path, const ExrReadOptions& options);

struct ExrWriteOptions {
  std::string layer = "ViewLayer";
  bool half = false;           // 16-bit float channels instead of 32-bit
  bool combined_pass = false;  // also "<layer>.Combined.RGBA" (zeros), as Blender writes by default
  std::string compression = "zip";
};

// Writes a label image the way Blender does (float channels "<layer>.IndexMA.X" and, with depth,
// "<layer>.Depth.Z"), atomically. For tests, benchmarks and tools that synthesise label renders.
Status WriteLabelExr(const std::filesystem::path& path,
                     const LabelImage& image,
                     const ExrWriteOptions& options = {});

}  // namespace handdb
