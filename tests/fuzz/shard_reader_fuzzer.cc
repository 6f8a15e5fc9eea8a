// libFuzzer target for the shard reader and validator (scripts/fuzz.sh). Every input is parsed
// twice: as given (exercises the header and checksum checks) and with its checksums recomputed by
// shard::RewriteChecksums, so mutations of the header, table and view records get past the hashes
// and reach the structural checks, the view-range checks and the accessors.
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "format/shard_layout.h"
#include "format/shard_reader.h"
#include "format/validator.h"

namespace {

void Exercise(std::span<const uint8_t> bytes) {
  auto reader = handdb::ShardReader::FromMemory(bytes, "fuzz.hdb");
  if (reader.ok()) {
    (void)reader->VerifyChecksums();
    int64_t acc = 0;
    std::vector<handdb::PointQ> decoded;
    uint8_t field[handdb::shard::kCoarseFieldSize];
    for (size_t i = 0; i < reader->num_views(); ++i) {
      const handdb::ViewLabel label = reader->label(i);
      acc += label.render_id;
      if (reader->coded()) {  // a coded shard (v1.2): its codes decode or fail cleanly
        if (reader->DecodePoints(i, &decoded).ok()) {
          for (const handdb::PointQ& p : decoded) acc += p.x - p.y;
        }
        if (reader->DecodeCoarseField(i, field).ok()) acc += field[0];
        acc += static_cast<int64_t>(reader->point_code(i).size() + reader->field_code(i).size());
        continue;
      }
      for (const handdb::PointQ& p : reader->points(i)) acc += p.x - p.y;
      acc += static_cast<int64_t>(reader->point_offset(i));
    }
    acc += static_cast<int64_t>(reader->all_points().size() + reader->metadata_json().size());
    (void)reader->ScanViews(
        [&](size_t, const handdb::ViewLabel&, std::span<const handdb::PointQ> pts) {
          acc += static_cast<int64_t>(pts.size());
          return handdb::Status::Ok();
        },
        {.verify_checksums = true});
    if (acc == 0x7fffffffffffffff) std::abort();  // keeps the reads alive
  }
  handdb::ValidateOptions options;
  options.max_problems_per_check = 4;
  (void)handdb::ValidateShardBytes(bytes, "fuzz.hdb", options);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  // An exact-size heap copy (8-byte aligned), so reads past the end are caught by ASan.
  std::vector<uint8_t> bytes(data, data + size);
  Exercise(bytes);
  if (handdb::shard::RewriteChecksums(bytes)) Exercise(bytes);
  return 0;
}
