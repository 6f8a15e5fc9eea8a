// Streams canonical views into one shard file (docs/format.md). Points go to disk as they
// arrive; only the fixed-size view table is kept in memory until Finish(), which writes the
// table, metadata, section table and footer, then commits atomically (temp, fsync, rename).
// Same inputs in the same order -> byte-identical file.
#pragma once

#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/view.h"

namespace handdb {

// A section this writer does not know (element_size 1), written after the view table and the
// coarse fields. Used by the forward-compatibility tests; the type must not be 1, 2, 3 or 4.
struct ShardExtraSection {
  uint32_t type = 0;
  uint32_t flags = 0;  // shard::kSectionFlagRequired or 0
  std::string data;
};

struct ShardWriterOptions {
  std::string metadata_json = "{}";  // generation config, hand-model hash, versions, label names
  std::vector<ShardExtraSection> extra_sections;
  // Write the v1.1 coarse-fields section (format/coarse_field.h, 1,849 bytes per view), which the
  // search's query -> view bound reads instead of computing it on open. Off: a v1.1 shard with
  // the three v1.0 sections only (tests of the fallback).
  bool coarse_fields = true;
  // Write a v1.2 coded shard (docs/format.md section 10): each view's points as its
  // EncodeViewPoints code (~160 bytes for a converted view instead of ~2,200) and its coarse
  // field as its EncodeCoarseField code (~600 instead of 1,849), read back by decoding. For
  // databases searched through an index (handdb index), which decodes only its candidates; an
  // exact search decodes what it reads. Implies coarse fields (coarse_fields is ignored).
  bool coded = false;
  bool Check() const;
};

struct ShardSummary {
  std::filesystem::path path;
  uint64_t num_views = 0;
  uint64_t num_points = 0;
  uint64_t file_size = 0;
  std::string checksum;  // xxh3-64 of the whole file, 16 lowercase hex digits
};

class ShardWriter {
 public:
  ShardWriter();
  ~ShardWriter();  // an unfinished shard leaves no file behind
  ShardWriter(const ShardWriter&) = delete;
  ShardWriter& operator=(const ShardWriter&) = delete;

  Status Open(const std::filesystem::path& path, const ShardWriterOptions& options);
  // Points in the canonical normalised frame; label.render_id etc. filled by the caller.
  // Refuses (kOutOfRange / kNonZeroReserved) coordinates beyond +-6144 (384 px), non-finite label
  // values and non-zero label.flags, so a writer never produces a shard the validator rejects
  // for those reasons.
  Status AddView(const ViewLabel& label, std::span<const PointQ> points);
  Result<ShardSummary> Finish();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace handdb
