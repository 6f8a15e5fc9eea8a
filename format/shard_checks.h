// The checks of a shard's bytes, shared by the writer (its own output), the reader (at open) and
// the validator (everything): one small function per concern and error code, chained, after
// OpenEXRCore's validation.c. The byte layout they check is format/shard_layout.h.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "base/status.h"
#include "format/shard_layout.h"

namespace handdb::shard {

// Problems found in one file. Messages read "<file>: offset <o>: <problem>". With stop_at_first
// the first Add() ends checking (the reader); otherwise everything is collected (the validator),
// with at most max_per_check listed per check tag and the rest only counted.
struct Problem {
  StatusCode code = StatusCode::kOk;
  uint64_t offset = 0;
  std::string message;
  std::string what;  // the message without "<file>: offset <o>: "
};

class ProblemList {
 public:
  ProblemList(std::string file, bool stop_at_first, size_t max_per_check = 0)
      : file_(std::move(file)), stop_at_first_(stop_at_first), max_per_check_(max_per_check) {}
  void Add(const char* check, StatusCode code, uint64_t offset, const std::string& what);
  // A problem not tied to an offset ("<file>: <problem>").
  void AddFileLevel(const char* check, StatusCode code, const std::string& what);
  // True when the caller should stop checking (stop_at_first and something was found).
  bool done() const { return stop_at_first_ && !problems_.empty(); }
  bool empty() const { return problems_.empty() && suppressed_ == 0; }
  const std::vector<Problem>& problems() const { return problems_; }
  uint64_t suppressed() const { return suppressed_; }
  const std::string& file() const { return file_; }
  Status FirstStatus() const;

 private:
  bool Admit(const char* check);
  std::string file_;
  bool stop_at_first_;
  size_t max_per_check_;
  std::map<std::string, size_t> per_check_;
  std::vector<Problem> problems_;
  uint64_t suppressed_ = 0;
};

// What the structural checks learned; valid() means the known sections and the view table may be
// accessed within the bounds recorded here.
struct Layout {
  RawHeader header;
  std::vector<RawSection> sections;  // in table (= file) order
  int metadata = -1;                 // indices into sections
  int views = -1;
  int points = -1;
  int coarse_fields = -1;  // optional (v1.1)
  int point_codes = -1;    // v1.2, coded shards (header bit kFeatureCodedViews) only
  int field_codes = -1;
  bool coded = false;  // the header has kFeatureCodedViews
  uint32_t view_stride = kViewRecordSize;
  bool structure_ok = false;  // header, table, section bounds and footer are usable
  bool views_ok = false;      // every view's point range lies inside the points section
                              // (coded: every view's code and field code lie inside theirs)
};

// Cheap checks at open: header (magic, version, size, features, reserved, checksum), section table
// (checksum, entries, alignment, monotonic and exact coverage, zero padding, known element sizes,
// required sections), footer (magic, length), counts vs sections, and every view's point range.
Layout CheckLayout(std::span<const uint8_t> bytes, ProblemList* problems);

// Hashes every section (and checks the header and table checksums once more); each mismatch names
// the section, its offset and both values.
void CheckSectionChecksums(std::span<const uint8_t> bytes,
                           const Layout& layout,
                           ProblemList* problems);

// Label ranges (docs/format.md §3.2): keypoints |x|, |y| <= 384 px (as for points), |z| <= 2048 px;
// angles (camera_roll, and joint angles without a hand model's limits) within +-2 pi.
constexpr float kMaxAbsKeypointXY = 384.0f;
constexpr float kMaxAbsKeypointZ = 2048.0f;
constexpr double kMaxAbsAngle = 2 * 3.14159265358979323846;

// The range checks of one view label that need only its record, shared by the reader's open
// checks and the validator (so a NaN joint angle is never served as `nan`): every f32
// finite ("label-finite"), ids not 0xffffffff ("label-id"), each joint angle inside
// [limits->min, limits->max] +- tolerance, or +-2 pi without limits ("label-joints"),
// |camera_roll| <= 2 pi ("label-roll"), keypoints in range ("label-keypoints"). `at` is the
// record's offset in the file, `index` the view's; `limits_source` names the limits in messages.
// Returns false when a float is not finite (its value checks are then skipped).
bool CheckLabelRanges(const uint8_t* record,
                      uint64_t at,
                      uint64_t index,
                      const JointLimits* limits,
                      double tolerance,
                      const std::string& limits_source,
                      ProblemList* problems);

// CheckLabelRanges of every view (no hand model), for the reader's open. Needs a layout with
// structure_ok.
void CheckViewLabels(std::span<const uint8_t> bytes, const Layout& layout, ProblemList* problems);

}  // namespace handdb::shard
