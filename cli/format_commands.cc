// `handdb info` and `handdb validate` (docs/format.md): look inside shards and database
// directories.
#include <CLI/CLI.hpp>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/hex.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "format/manifest.h"
#include "format/shard_layout.h"
#include "format/shard_reader.h"
#include "format/validator.h"
#include "query/index/view_index.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// The metadata as JSON when it parses, else as a string (info never fails on bad metadata;
// validate reports it).
json MetadataJson(std::string_view text) {
  json doc = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded()) return json(std::string(text));
  return doc;
}

// One line per top-level key, values as compact JSON.
void PrintMetadata(const json& metadata, const char* prefix) {
  if (!metadata.is_object() || metadata.empty()) {
    std::printf("%s%s\n", prefix, metadata.dump().c_str());
    return;
  }
  const std::string indent(std::strlen(prefix), ' ');
  bool first = true;
  for (const auto& [key, value] : metadata.items()) {
    std::printf("%s%s: %s\n", first ? prefix : indent.c_str(), key.c_str(), value.dump().c_str());
    first = false;
  }
}

int InfoShard(const fs::path& path, bool as_json) {
  auto reader = ShardReader::Open(path);
  if (!reader.ok()) {
    return Fail("info",
                Status(reader.status().code(),
                       reader.status().message() + " (run 'handdb validate' for every problem)"));
  }
  auto whole = shard::FileChecksum(path.string());
  if (!whole.ok()) return Fail("info", whole.status());
  const ShardHeaderInfo& h = reader->header();
  const double mean =
      h.num_views ? static_cast<double>(h.num_points) / static_cast<double>(h.num_views) : 0.0;
  if (as_json) {
    json sections = json::array();
    for (const auto& s : reader->sections()) {
      sections.push_back({{"name", s.name},
                          {"type", s.type},
                          {"flags", s.flags},
                          {"required", (s.flags & shard::kSectionFlagRequired) != 0},
                          {"offset", s.offset},
                          {"size", s.size},
                          {"count", s.count},
                          {"element_size", s.element_size},
                          {"xxh3", shard::ChecksumHex(s.checksum)}});
    }
    json out = {
        {"path", path.string()},
        {"kind", "shard"},
        {"version", std::to_string(h.version_major) + "." + std::to_string(h.version_minor)},
        {"file_size", h.file_size},
        {"xxh3", shard::ChecksumHex(*whole)},
        {"required_features", h.required_features},
        {"optional_features", h.optional_features},
        {"num_views", h.num_views},
        {"num_points", h.num_points},
        {"mean_points_per_view", mean},
        {"sections", std::move(sections)},
        {"metadata", MetadataJson(reader->metadata_json())}};
    std::printf("%s\n", out.dump(2).c_str());
    return kExitOk;
  }
  std::printf("shard %s\n", path.string().c_str());
  std::printf("  format      handdb shard v%u.%u\n", h.version_major, h.version_minor);
  std::printf("  file size   %" PRIu64 " bytes, xxh3 %s\n",
              h.file_size,
              shard::ChecksumHex(*whole).c_str());
  std::printf("  features    required %s, optional %s\n",
              HexPrefixed(h.required_features).c_str(),
              HexPrefixed(h.optional_features).c_str());
  std::printf("  views       %" PRIu64 "\n", h.num_views);
  std::printf("  points      %" PRIu64 " (%.1f per view)\n", h.num_points, mean);
  std::printf("  sections    %-16s %8s %12s %12s %10s %6s  %s\n",
              "name",
              "flags",
              "offset",
              "size",
              "count",
              "elem",
              "xxh3");
  for (const auto& s : reader->sections()) {
    std::printf("              %-16s %8s %12" PRIu64 " %12" PRIu64 " %10" PRIu64 " %6u  %s\n",
                s.name.c_str(),
                (s.flags & shard::kSectionFlagRequired) ? "required" : HexPrefixed(s.flags).c_str(),
                s.offset,
                s.size,
                s.count,
                s.element_size,
                shard::ChecksumHex(s.checksum).c_str());
  }
  PrintMetadata(MetadataJson(reader->metadata_json()), "  metadata    ");
  return kExitOk;
}

int InfoDatabase(const fs::path& dir, bool as_json) {
  // Shards with the v1.1 coarse-fields section: the search computes the others' on open. The
  // manifest and the shards come from one database even while a convert rewrites it.
  size_t with_fields = 0;
  size_t coded = 0;  // v1.2 coded shards (their fields are coded too)
  auto manifest = ReadWithStableManifest(dir, [&]() -> Result<Manifest> {
    with_fields = 0;
    coded = 0;
    Result<Manifest> read = ReadManifest(dir);
    if (!read.ok()) return read;
    for (const auto& s : read->shards) {
      auto reader = ShardReader::Open(dir / s.file);
      if (!reader.ok()) return reader.status();
      if (reader->has_coarse_fields() || reader->coded()) ++with_fields;
      if (reader->coded()) ++coded;
    }
    return read;
  });
  if (!manifest.ok()) return Fail("info", manifest.status());
  const Manifest& m = *manifest;
  uint64_t bytes = 0;
  uint64_t points = 0;
  for (const auto& s : m.shards) {
    bytes += s.bytes;
    points += s.points;
  }
  if (as_json) {
    json out = {{"path", dir.string()},
                {"kind", "database"},
                {"num_shards", m.shards.size()},
                {"total_bytes", bytes},
                {"total_points", points},
                {"shards_with_coarse_fields", with_fields},
                {"coded_shards", coded},
                {"manifest", ManifestToJson(m)}};
    std::printf("%s\n", out.dump(2).c_str());
    return kExitOk;
  }
  std::printf("database %s\n", dir.string().c_str());
  std::printf("  manifest      %s v%d, written by handdb %s\n",
              kManifestFormat,
              m.version,
              m.tool_version.c_str());
  std::printf("  shards        %zu (%" PRIu64 " bytes)\n", m.shards.size(), bytes);
  std::printf("  views         %" PRIu64 " canonical x %u rolls = %" PRIu64 " virtual views\n",
              m.num_views,
              m.rolls,
              m.num_virtual_views);
  std::printf("  points        %" PRIu64 " (%.1f per view)\n",
              points,
              m.num_views ? static_cast<double>(points) / static_cast<double>(m.num_views) : 0.0);
  std::printf("  skipped       %zu renders\n", m.skipped.size());
  if (coded > 0) {
    std::printf(
        "  coded         %zu of %zu shards (format v1.2: points and fields decoded when "
        "read)\n",
        coded,
        m.shards.size());
  }
  std::printf("  coarse fields stored in %zu of %zu shards%s\n",
              with_fields,
              m.shards.size(),
              with_fields == m.shards.size()
                  ? ""
                  : " (v1.0 shards: the search computes their fields on open, ~0.1 ms per view)");
  if (m.index) {
    std::printf("  index         %s (%s, %" PRIu64
                " bytes, %.2f per virtual view): `handdb query` "
                "searches indexed by default (--search exact for every pair)\n",
                m.index->file.c_str(),
                m.index->kind.c_str(),
                m.index->bytes,
                m.num_virtual_views
                    ? static_cast<double>(m.index->bytes) / static_cast<double>(m.num_virtual_views)
                    : 0.0);
  } else {
    std::printf("  index         none (exact search; `handdb index` builds one)\n");
  }
  std::printf("  labels       ");
  for (const auto& l : m.labels) {
    std::printf(" %s[%u]%s%s", l.name.c_str(), l.count, l.unit.empty() ? "" : ":", l.unit.c_str());
  }
  std::printf("\n");
  for (const auto& s : m.shards) {
    std::printf("  %-16s %8" PRIu64 " views %10" PRIu64 " points %12" PRIu64 " bytes  xxh3 %s\n",
                s.file.c_str(),
                s.views,
                s.points,
                s.bytes,
                s.xxh3.c_str());
  }
  PrintMetadata(m.metadata, "  metadata      ");
  return kExitOk;
}

}  // namespace

// A database's search index, when its manifest lists one: the file the manifest names, its size
// and checksum, its header and payload checksums, and that it was built for these shards
// (ViewIndex::Open).
void AppendIndexProblems(const std::string& path, ValidationReport* report) {
  std::error_code ec;
  if (!fs::is_directory(path, ec)) return;
  auto manifest = ReadManifest(path);
  if (!manifest.ok() || !manifest->index) return;  // manifest problems are reported already
  ++report->files;
  auto index = ViewIndex::Open(path, *manifest);
  if (!index.ok()) {
    report->problems.push_back({index.status().code(),
                                (fs::path(path) / manifest->index->file).string(),
                                0,
                                index.status().message()});
  }
}

int RunInfo(int argc, char** argv) {
  CLI::App app(
      "Print a shard's header, sections, counts and metadata, or a database directory's manifest "
      "summary. Runs the cheap checks only; use 'handdb validate' to check everything.",
      "handdb info");
  std::string path;
  bool as_json = false;
  app.add_option("PATH", path, "a shard file (.hdb) or a database directory")->required();
  app.add_flag("--json", as_json, "machine-readable output on stdout");
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  std::error_code ec;
  if (fs::is_directory(path, ec)) return InfoDatabase(path, as_json);
  return InfoShard(path, as_json);
}

int RunValidate(int argc, char** argv) {
  CLI::App app(
      "Check shard files or database directories completely: header, section table, checksums, "
      "layout, coordinate and label ranges (joint limits from the shard's hand model), and "
      "manifest <=> shards. Prints every problem with file, offset and raw values; exits 1 if "
      "there is any.",
      "handdb validate");
  std::vector<std::string> paths;
  bool as_json = false;
  bool all = false;
  bool quiet = false;
  bool no_checksums = false;
  size_t max_problems = ValidateOptions{}.max_problems_per_check;
  app.add_option("PATH", paths, "shard files (.hdb) or database directories")->required();
  app.add_flag("--json", as_json, "machine-readable report on stdout");
  app.add_option("--max-problems",
                 max_problems,
                 "problems listed per file and kind of check (the rest are counted)")
      ->capture_default_str();
  app.add_flag("--all", all, "list every problem (same as --max-problems 0)");
  app.add_flag("--no-checksums", no_checksums, "skip hashing (structure and ranges only)");
  app.add_flag("-q,--quiet", quiet, "no progress line and no summary");
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;

  ValidateOptions options;
  options.max_problems_per_check = all ? 0 : max_problems;
  options.verify_checksums = !no_checksums;
  options.show_progress = !quiet && !as_json;
  bool ok = true;
  json reports = json::array();
  for (const auto& path : paths) {
    ValidationReport r = ValidatePath(path, options);
    AppendIndexProblems(path, &r);
    ok = ok && r.ok();
    if (as_json) {
      json problems = json::array();
      for (const auto& p : r.problems) {
        problems.push_back({{"code", StatusCodeName(p.code)},
                            {"file", p.file},
                            {"offset", p.offset},
                            {"message", p.message}});
      }
      reports.push_back({{"path", path},
                         {"ok", r.ok()},
                         {"files", r.files},
                         {"views", r.views},
                         {"points", r.points},
                         {"num_problems", r.num_problems()},
                         {"suppressed", r.suppressed},
                         {"problems", std::move(problems)}});
      continue;
    }
    for (const auto& p : r.problems) {
      std::fprintf(stderr, "handdb validate: %s [%s]\n", p.message.c_str(), StatusCodeName(p.code));
    }
    if (r.suppressed > 0) {
      std::fprintf(stderr,
                   "handdb validate: %s: %" PRIu64
                   " more problem(s) not listed (use --all to list them)\n",
                   path.c_str(),
                   r.suppressed);
    }
    if (!quiet) {
      std::printf("%s: %s: %" PRIu64 " shard file(s), %" PRIu64 " views, %" PRIu64 " points",
                  r.ok() ? "OK" : "INVALID",
                  path.c_str(),
                  r.files,
                  r.views,
                  r.points);
      if (!r.ok()) std::printf(", %" PRIu64 " problem(s)", r.num_problems());
      std::printf("\n");
    }
  }
  if (as_json) {
    std::printf("%s\n", json{{"ok", ok}, {"paths", std::move(reports)}}.dump(2).c_str());
  }
  return ok ? kExitOk : kExitError;
}

}  // namespace handdb::cli
