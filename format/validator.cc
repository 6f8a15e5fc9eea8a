#include "format/validator.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <unordered_map>
#include <vector>

#include "base/json_schema.h"
#include "base/mapped_file.h"
#include "base/progress.h"
#include "format/coarse_field.h"
#include "format/field_codec.h"
#include "format/manifest.h"
#include "format/point_codec.h"
#include "format/shard_checks.h"
#include "format/shard_layout.h"

namespace handdb {

using namespace shard;  // NOLINT(google-build-using-namespace): the layout constants
namespace fs = std::filesystem;

bool ValidateOptions::Check() const {
  CHECK_OPTION_GE(joint_limit_tolerance, 0.0);
  CHECK_OPTION(std::isfinite(joint_limit_tolerance));
  return true;
}

void ValidationReport::Append(ValidationReport other) {
  for (auto& p : other.problems) problems.push_back(std::move(p));
  suppressed += other.suppressed;
  files += other.files;
  views += other.views;
  points += other.points;
}

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kAngleTolerance = 1e-3;  // rad, for derived angles (theta, phi)

// A shard's recorded joint limits and the hand model they came from (for messages).
struct RecordedLimits {
  JointLimits limits;
  std::string source;
};

// hand_model.joint_limits from the shard's metadata, when present.
// The parsed object goes to *parsed (left null when it is not a JSON object).
std::optional<RecordedLimits> ParseMetadata(std::string_view text,
                                            uint64_t offset,
                                            ProblemList* problems,
                                            nlohmann::json* parsed) {
  if (Status s = CheckJsonText(text, "metadata section"); !s.ok()) {
    problems->Add("metadata", StatusCode::kBadJson, offset, s.message());
    return std::nullopt;
  }
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    problems->Add("metadata",
                  StatusCode::kBadJson,
                  offset + std::min<uint64_t>(e.byte, text.size()),
                  std::string("metadata section is not valid JSON: ") + e.what());
    return std::nullopt;
  } catch (const nlohmann::json::out_of_range& e) {  // a number beyond a double's range
    problems->Add("metadata",
                  StatusCode::kBadJson,
                  offset,
                  std::string("metadata section is not valid JSON: ") + e.what());
    return std::nullopt;
  }
  if (!doc.is_object()) {
    problems->Add("metadata",
                  StatusCode::kSchemaViolation,
                  offset,
                  "metadata JSON is a " + std::string(doc.type_name()) + ", expected an object");
    return std::nullopt;
  }
  *parsed = doc;
  auto hm = doc.find("hand_model");
  if (hm == doc.end()) return std::nullopt;
  if (!hm->is_object()) {
    problems->Add(
        "metadata", StatusCode::kSchemaViolation, offset, "metadata /hand_model is not an object");
    return std::nullopt;
  }
  auto jl = hm->find("joint_limits");
  if (jl == hm->end()) return std::nullopt;
  auto bad = [&](const std::string& why) {
    problems->Add(
        "metadata",
        StatusCode::kSchemaViolation,
        offset,
        "metadata /hand_model/joint_limits " + why + " (value: " + jl->dump().substr(0, 200) + ")");
    return std::nullopt;
  };
  if (!jl->is_array() || jl->size() != kNumJointAngles) {
    return bad("must be an array of " + std::to_string(kNumJointAngles) + " [lo, hi] pairs");
  }
  RecordedLimits out;
  out.source = hm->value("name", std::string("hand model"));
  for (int j = 0; j < kNumJointAngles; ++j) {
    const auto& pair = (*jl)[j];
    if (!pair.is_array() || pair.size() != 2 || !pair[0].is_number() || !pair[1].is_number()) {
      return bad("[" + std::to_string(j) + "] is not a [lo, hi] pair of numbers");
    }
    out.limits.min[j] = pair[0].get<double>();
    out.limits.max[j] = pair[1].get<double>();
    if (!(out.limits.min[j] <= out.limits.max[j])) {
      return bad("[" + std::to_string(j) + "] has lo > hi");
    }
  }
  return out;
}

void CheckLabel(const uint8_t* rec,
                uint64_t at,
                uint64_t i,
                const std::optional<RecordedLimits>& lim,
                const ValidateOptions& options,
                ProblemList* problems) {
  const std::string view = "view " + std::to_string(i) + ": ";
  const bool finite = CheckLabelRanges(rec,
                                       at,
                                       i,
                                       lim ? &lim->limits : nullptr,
                                       lim ? options.joint_limit_tolerance : 0.0,
                                       lim ? lim->source + " joint limits" : "",
                                       problems);
  if (!finite) return;
  const ViewLabel l = DecodeViewLabel(rec);
  const auto& d = l.view_direction;
  const double norm = std::sqrt(double{d[0]} * d[0] + double{d[1]} * d[1] + double{d[2]} * d[2]);
  if (std::abs(norm - 1.0) > 1e-3) {
    problems->Add("label-direction",
                  StatusCode::kOutOfRange,
                  at + kViewOffViewDirection,
                  view + "view_direction (" + FormatValue(d[0]) + ", " + FormatValue(d[1]) + ", " +
                      FormatValue(d[2]) + ") has length " + FormatValue(norm) + ", expected 1");
  } else {
    const double theta = std::acos(std::clamp(d[2] / norm, -1.0, 1.0));
    if (std::abs(theta - l.view_theta) > kAngleTolerance) {
      problems->Add("label-direction",
                    StatusCode::kOutOfRange,
                    at + kViewOffViewTheta,
                    view + "view_theta is " + FormatValue(l.view_theta) +
                        ", acos(view_direction.z) is " + FormatValue(theta));
    }
    if (std::sin(theta) > 1e-2) {
      const double phi = std::atan2(double{d[1]}, double{d[0]});
      const double diff = std::remainder(phi - l.view_phi, 2 * kPi);
      if (std::abs(diff) > kAngleTolerance || std::abs(l.view_phi) > kPi + kAngleTolerance) {
        problems->Add("label-direction",
                      StatusCode::kOutOfRange,
                      at + kViewOffViewPhi,
                      view + "view_phi is " + FormatValue(l.view_phi) +
                          ", atan2(view_direction.y, view_direction.x) is " + FormatValue(phi));
      }
    }
  }
  if (!(l.source_diameter_px > 0) || !(l.scale > 0) ||
      std::abs(double{l.scale} * l.source_diameter_px - kNormalisedDiameter) >
          1e-3 * kNormalisedDiameter) {
    problems->Add("label-scale",
                  StatusCode::kOutOfRange,
                  at + kViewOffSourceDiameter,
                  view + "scale " + FormatValue(l.scale) + " x source_diameter_px " +
                      FormatValue(l.source_diameter_px) + " = " +
                      FormatValue(double{l.scale} * l.source_diameter_px) + ", expected " +
                      FormatValue(kNormalisedDiameter) + " (both > 0)");
  }
}

void CheckPoints(const uint8_t* b,
                 uint64_t offset,
                 uint64_t first,
                 uint64_t count,
                 const std::string& owner,
                 ProblemList* problems) {
  for (uint64_t k = 0; k < count; ++k) {
    const uint64_t at = offset + (first + k) * kPointSize;
    const auto x = LoadLittleEndian<int16_t>(b + at);
    const auto y = LoadLittleEndian<int16_t>(b + at + 2);
    if (std::abs(x) > kMaxAbsPointCoord || std::abs(y) > kMaxAbsPointCoord) {
      problems->Add("points-range",
                    StatusCode::kOutOfRange,
                    at,
                    owner + "point " + std::to_string(first + k) + " (" + std::to_string(x) + ", " +
                        std::to_string(y) + ") exceeds |x|,|y| <= " +
                        std::to_string(kMaxAbsPointCoord) + " (1/16 px, i.e. 384 px)");
    }
  }
}

// The stored coarse field of view i equals the one computed from its points (the search prunes
// with it, so a wrong byte could drop a true match: a checksum recomputed over corrupt bytes must
// not hide that).
void CheckCoarseField(const uint8_t* b,
                      uint64_t points_at,
                      uint32_t count,
                      const Layout& layout,
                      uint64_t i,
                      ProblemList* problems) {
  std::vector<PointQ> points(count);
  if (count > 0) std::memcpy(points.data(), b + points_at, count * sizeof(PointQ));
  uint8_t want[kCoarseFieldSize];
  ComputeCoarseField(points, want);
  const uint64_t at =
      layout.sections[static_cast<size_t>(layout.coarse_fields)].offset + i * kCoarseFieldSize;
  for (uint32_t c = 0; c < kCoarseFieldSize; ++c) {
    if (b[at + c] != want[c]) {
      problems->Add("coarse-field",
                    StatusCode::kOutOfRange,
                    at + c,
                    "view " + std::to_string(i) + ": coarse field cell " + std::to_string(c) +
                        " is " + std::to_string(b[at + c]) + ", its points give " +
                        std::to_string(want[c]) + " (1/2 px)");
      return;
    }
  }
}

// A coded shard's view i (v1.2, docs/format.md section 10): its point code decodes to its
// record's count of points, each in range, and its field code decodes to the field its points
// give. `code_at`, `field_at`: file offsets of the two codes.
void CheckCodedView(std::span<const uint8_t> bytes,
                    const Layout& layout,
                    uint64_t i,
                    const uint8_t* rec,
                    ProblemList* problems) {
  const uint8_t* b = bytes.data();
  const RawSection& vs = layout.sections[layout.views];
  const RawSection& pc = layout.sections[static_cast<size_t>(layout.point_codes)];
  const RawSection& fc = layout.sections[static_cast<size_t>(layout.field_codes)];
  const std::string view = "view " + std::to_string(i) + ": ";
  const uint64_t begin = LoadLittleEndian<uint64_t>(rec + kViewOffPointOffset);
  const uint64_t end = i + 1 < vs.count
                           ? LoadLittleEndian<uint64_t>(
                                 b + vs.offset + (i + 1) * layout.view_stride + kViewOffPointOffset)
                           : pc.size;
  const uint64_t code_at = pc.offset + begin;
  std::vector<PointQ> points;
  const Status decoded = DecodeViewPoints(bytes.subspan(code_at, end - begin),
                                          LoadLittleEndian<float>(rec + kViewOffScale),
                                          {LoadLittleEndian<float>(rec + kViewOffSourceCentre),
                                           LoadLittleEndian<float>(rec + kViewOffSourceCentre + 4)},
                                          &points);
  if (!decoded.ok()) {
    problems->Add("point-code", decoded.code(), code_at, view + "point code: " + decoded.message());
    return;
  }
  const uint32_t count = LoadLittleEndian<uint32_t>(rec + kViewOffPointCount);
  if (points.size() != count) {
    problems->Add("point-code",
                  StatusCode::kSizeMismatch,
                  code_at,
                  view + "point code decodes to " + std::to_string(points.size()) +
                      " points, its record says " + std::to_string(count));
    return;
  }
  for (size_t k = 0; k < points.size(); ++k) {
    if (std::abs(points[k].x) > kMaxAbsPointCoord || std::abs(points[k].y) > kMaxAbsPointCoord) {
      problems->Add("points-range",
                    StatusCode::kOutOfRange,
                    code_at,
                    view + "decoded point " + std::to_string(k) + " (" +
                        std::to_string(points[k].x) + ", " + std::to_string(points[k].y) +
                        ") exceeds |x|,|y| <= " + std::to_string(kMaxAbsPointCoord) +
                        " (1/16 px, i.e. 384 px)");
      return;
    }
  }
  const uint64_t field_begin = LoadLittleEndian<uint64_t>(b + fc.offset + 8 * i);
  const uint64_t field_end = LoadLittleEndian<uint64_t>(b + fc.offset + 8 * (i + 1));
  std::array<uint8_t, kCoarseFieldSize> field;
  const Status field_decoded =
      DecodeCoarseField(bytes.subspan(fc.offset + field_begin, field_end - field_begin), field);
  if (!field_decoded.ok()) {
    problems->Add("coarse-field",
                  field_decoded.code(),
                  fc.offset + field_begin,
                  view + "field code: " + field_decoded.message());
    return;
  }
  std::array<uint8_t, kCoarseFieldSize> want;
  ComputeCoarseField(points, want.data());
  for (uint32_t c = 0; c < kCoarseFieldSize; ++c) {
    if (field[c] != want[c]) {
      problems->Add("coarse-field",
                    StatusCode::kOutOfRange,
                    fc.offset + field_begin,
                    view + "coarse field cell " + std::to_string(c) + " decodes to " +
                        std::to_string(field[c]) + ", its points give " + std::to_string(want[c]) +
                        " (1/2 px)");
      return;
    }
  }
}

ValidationReport ToReport(const ProblemList& problems) {
  ValidationReport report;
  for (const auto& p : problems.problems()) {
    report.problems.push_back({p.code, problems.file(), p.offset, p.message});
  }
  report.suppressed = problems.suppressed();
  return report;
}

using RenderIdMap = std::unordered_map<render_id_t, std::string>;

ValidationReport ValidateBytes(std::span<const uint8_t> bytes,
                               const std::string& name,
                               const ValidateOptions& options,
                               RenderIdMap* seen,
                               nlohmann::json* metadata = nullptr) {
  THROW_CHECK(options.Check());
  ProblemList problems(name, /*stop_at_first=*/false, options.max_problems_per_check);
  const Layout layout = CheckLayout(bytes, &problems);
  ValidationReport counts;
  counts.files = 1;
  const uint8_t* b = bytes.data();
  if (layout.header.header_size >= kHeaderSize && options.verify_checksums &&
      layout.header.version_major == kVersionMajor && bytes.size() >= kMinFileSize) {
    // Header and table checksums were compared by CheckLayout; hash the sections in bounds.
    Layout sections_only = layout;
    sections_only.header.header_checksum =
        HeaderChecksum(bytes.subspan(0, std::min<size_t>(bytes.size(), layout.header.header_size)));
    CheckSectionChecksums(bytes, sections_only, &problems);
  }
  if (layout.structure_ok) {
    const RawSection& ms = layout.sections[layout.metadata];
    const std::string_view meta(reinterpret_cast<const char*>(b + ms.offset), ms.size);
    nlohmann::json parsed;
    const std::optional<RecordedLimits> limits = ParseMetadata(meta, ms.offset, &problems, &parsed);
    if (metadata != nullptr) *metadata = std::move(parsed);
    const RawSection& vs = layout.sections[layout.views];
    const RawSection* ps = layout.coded ? nullptr : &layout.sections[layout.points];
    for (uint64_t i = 0; i < vs.count; ++i) {
      const uint64_t at = vs.offset + i * layout.view_stride;
      CheckLabel(b + at, at, i, limits, options, &problems);
      const auto render_id = LoadLittleEndian<uint32_t>(b + at + kViewOffRenderId);
      if (seen != nullptr && render_id != kInvalidRenderId) {
        const std::string here = name + " view " + std::to_string(i);
        auto [it, inserted] = seen->emplace(render_id, here);
        if (!inserted) {
          problems.Add("render-id",
                       StatusCode::kBadLayout,
                       at + kViewOffRenderId,
                       "view " + std::to_string(i) + ": render_id " + std::to_string(render_id) +
                           " already appears in " + it->second);
        }
      }
      if (layout.views_ok && layout.coded) {
        CheckCodedView(bytes, layout, i, b + at, &problems);
      } else if (layout.views_ok) {
        const uint64_t off = LoadLittleEndian<uint64_t>(b + at + kViewOffPointOffset);
        const uint32_t cnt = LoadLittleEndian<uint32_t>(b + at + kViewOffPointCount);
        CheckPoints(b, ps->offset, off, cnt, "view " + std::to_string(i) + ": ", &problems);
        if (layout.coarse_fields >= 0) {
          CheckCoarseField(b, ps->offset + off * kPointSize, cnt, layout, i, &problems);
        }
      }
    }
    if (!layout.views_ok && ps != nullptr) CheckPoints(b, ps->offset, 0, ps->count, "", &problems);
    counts.views = vs.count;
    counts.points = layout.coded ? layout.header.num_points : ps->count;
  }
  ValidationReport report = ToReport(problems);
  report.files = counts.files;
  report.views = counts.views;
  report.points = counts.points;
  return report;
}

ValidationReport FileProblem(const std::string& file, const Status& status) {
  ValidationReport r;
  r.problems.push_back({status.code(), file, 0, status.message()});
  return r;
}

}  // namespace

ValidationReport ValidateShardBytes(std::span<const uint8_t> bytes,
                                    const std::string& name,
                                    const ValidateOptions& options) {
  return ValidateBytes(bytes, name, options, nullptr);
}

ValidationReport ValidateShardFile(const fs::path& path, const ValidateOptions& options) {
  auto file = MappedFile::Open(path, MappedFile::Advice::kSequential);
  if (!file.ok()) return FileProblem(path.string(), file.status());
  RenderIdMap seen;
  return ValidateBytes(file->bytes(), path.string(), options, &seen);
}

namespace {

ValidationReport ValidateDatabaseOnce(const fs::path& db_dir, const ValidateOptions& options) {
  ValidationReport report;
  const std::string manifest_path = (db_dir / kManifestFileName).string();
  Result<Manifest> manifest = ReadManifest(db_dir);
  if (!manifest.ok()) report.Append(FileProblem(manifest_path, manifest.status()));

  // The shard files present.
  static const std::regex kShardName(R"(shard-[0-9]+\.hdb)");
  std::set<std::string> present;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(db_dir, ec)) {
    const std::string file = entry.path().filename().string();
    if (std::regex_match(file, kShardName)) present.insert(file);
  }
  if (ec) {
    report.Append(
        FileProblem(db_dir.string(),
                    Status(StatusCode::kIoError,
                           db_dir.string() + ": cannot list directory: " + ec.message())));
    return report;
  }

  // Listed shards in manifest order; without a readable manifest, every shard present.
  std::vector<const ManifestShard*> listed;
  std::vector<ManifestShard> unlisted_entries;
  if (manifest.ok()) {
    std::set<std::string> names;
    for (const auto& s : manifest->shards) {
      listed.push_back(&s);
      names.insert(s.file);
    }
    for (const auto& file : present) {
      // Between a rewrite's two manifests (docs/format.md section 8) the one in place lists a
      // unit's staging file while its plain name is replaced: not a stray shard.
      const std::string staging =
          file.substr(0, file.size() - std::strlen(".hdb")) + kShardStagingSuffix;
      if (!names.count(file) && !names.count(staging)) {
        report.problems.push_back(
            {StatusCode::kBadLayout,
             (db_dir / file).string(),
             0,
             (db_dir / file).string() + ": shard file is not listed in " + manifest_path});
      }
    }
  } else {
    for (const auto& file : present) unlisted_entries.push_back({file, 0, 0, 0, ""});
    for (const auto& e : unlisted_entries) listed.push_back(&e);
  }

  uint64_t total_views = 0;
  for (const auto* s : listed) total_views += s->views;
  // Nothing to check (no readable manifest, no shard): no "0/0" line before the one error line.
  Progress progress("validate",
                    manifest.ok() ? total_views : listed.size(),
                    options.show_progress && !listed.empty(),
                    manifest.ok() ? "views" : "shards");
  RenderIdMap seen;
  // Every manifest field against what the shards record.
  std::optional<ManifestShardCheck> cross_check;
  if (manifest.ok()) {
    cross_check.emplace(*manifest);
    if (const std::string labels = ManifestLabelsMismatch(*manifest); !labels.empty()) {
      report.problems.push_back(
          {StatusCode::kSizeMismatch, manifest_path, 0, manifest_path + ": " + labels});
    }
  }
  for (const ManifestShard* entry : listed) {
    const fs::path path = db_dir / entry->file;
    const std::string file = path.string();
    auto mapped = MappedFile::Open(path, MappedFile::Advice::kSequential);
    if (!mapped.ok()) {
      const Status& s = mapped.status();
      report.Append(
          FileProblem(file,
                      s.code() == StatusCode::kNotFound
                          ? Status(s.code(), file + ": listed in " + manifest_path + " but missing")
                          : s));
      continue;
    }
    const auto bytes = mapped->bytes();
    if (manifest.ok()) {
      auto mismatch = [&](StatusCode code, uint64_t offset, const std::string& what) {
        report.problems.push_back({code, file, offset, file + ": " + what});
      };
      if (bytes.size() != entry->bytes) {
        mismatch(StatusCode::kSizeMismatch,
                 0,
                 "file is " + std::to_string(bytes.size()) + " bytes, " + manifest_path +
                     " lists " + std::to_string(entry->bytes));
      }
      if (options.verify_checksums) {
        const std::string actual = ChecksumHex(Checksum(bytes.data(), bytes.size()));
        if (actual != entry->xxh3) {
          mismatch(StatusCode::kChecksumMismatch,
                   0,
                   "whole-file xxh3 is " + actual + ", " + manifest_path + " lists " + entry->xxh3);
        }
      }
      if (bytes.size() >= kMinFileSize) {
        const RawHeader h = RawHeader::DecodeFrom(bytes);
        if (h.num_views != entry->views) {
          mismatch(StatusCode::kSizeMismatch,
                   kOffNumViews,
                   "header num_views is " + std::to_string(h.num_views) + ", " + manifest_path +
                       " lists " + std::to_string(entry->views));
        }
        if (h.num_points != entry->points) {
          mismatch(StatusCode::kSizeMismatch,
                   kOffNumPoints,
                   "header num_points is " + std::to_string(h.num_points) + ", " + manifest_path +
                       " lists " + std::to_string(entry->points));
        }
      }
    }
    nlohmann::json metadata;
    ValidationReport shard_report = ValidateBytes(bytes, file, options, &seen, &metadata);
    if (cross_check) {
      for (const std::string& what : cross_check->Check(*entry, metadata)) {
        report.problems.push_back({StatusCode::kSizeMismatch, file, 0, file + ": " + what});
      }
    }
    progress.Add(manifest.ok() ? entry->views : 1);
    report.Append(std::move(shard_report));
  }
  progress.Finish();
  if (cross_check) {
    for (const std::string& what : cross_check->Finish()) {
      report.problems.push_back(
          {StatusCode::kSizeMismatch, manifest_path, 0, manifest_path + ": " + what});
    }
  }
  return report;
}

}  // namespace

ValidationReport ValidateDatabase(const fs::path& db_dir, const ValidateOptions& options) {
  // A convert rewriting DB_DIR meanwhile: validate the database whose manifest is in place at
  // the end, not a mix of two.
  return ReadWithStableManifest(db_dir, [&] { return ValidateDatabaseOnce(db_dir, options); });
}

ValidationReport ValidatePath(const fs::path& path, const ValidateOptions& options) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return ValidateDatabase(path, options);
  if (!fs::exists(path, ec)) {
    return FileProblem(
        path.string(),
        Status(StatusCode::kNotFound, path.string() + ": no such file or directory"));
  }
  return ValidateShardFile(path, options);
}

}  // namespace handdb
