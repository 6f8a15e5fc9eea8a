#include "generator/convert/converter.h"

#include <OpenEXR/ImfThreading.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <system_error>

#include "base/atomic_file.h"
#include "base/hex.h"
#include "base/json_schema.h"
#include "base/progress.h"
#include "base/sha256.h"
#include "base/thread_pool.h"
#include "edges/exr_io.h"
#include "edges/normalise.h"
#include "format/manifest.h"
#include "format/shard_reader.h"
#include "format/shard_writer.h"
#include "generator/hand/database_rig.h"
#include "generator/hand/hand_model.h"
#include "generator/plan/plan.h"
#include "handdb_version.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr int kShardMetadataVersion = 1;

}  // namespace

bool ConvertOptions::Check() const {
  CHECK_OPTION(num_threads == -1 || num_threads >= 1);
  CHECK_OPTION(edges.Check());
  return true;
}

std::string ShardFileName(uint32_t unit_id) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "shard-%05u.hdb", unit_id);
  return buf;
}

std::string ShardStagingFileName(uint32_t unit_id) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "shard-%05u%s", unit_id, kShardStagingSuffix);
  return buf;
}

namespace {

// ---------------------------------------------------------------------------------------------
// Converting a render directory.

struct RunContext {
  fs::path render_dir;
  Plan plan;
  std::string plan_sha256;
  HandModel hand;
  ViewConversionOptions view_options;
  ExrReadOptions exr_options;
};

struct ConvertedRender {
  CanonicalView view;
  std::string blender_version;
  std::string script_version;
};

std::string RelativeRenderFile(uint32_t unit, uint32_t render_id, const char* ext) {
  return "units/" + UnitDirName(unit) + "/" + RenderFileStem(render_id) + ext;
}

Result<ConvertedRender> ConvertRender(const RunContext& ctx,
                                      const PlanUnit& unit,
                                      const PlanRender& r) {
  const fs::path sidecar_path = ctx.render_dir / RelativeRenderFile(unit.id, r.render_id, ".json");
  const fs::path exr_path = ctx.render_dir / RelativeRenderFile(unit.id, r.render_id, ".exr");
  auto sidecar = ReadSidecar(sidecar_path);
  if (!sidecar.ok()) return sidecar.status();
  const std::string what = sidecar_path.string();
  auto mismatch = [&](const char* field, const std::string& got, const std::string& want) {
    return Status(StatusCode::kSchemaViolation,
                  what + ": " + field + " " + got + " disagrees with the plan (" + want + ")");
  };
  if (sidecar->render_id != r.render_id) {
    return mismatch("render_id", std::to_string(sidecar->render_id), std::to_string(r.render_id));
  }
  if (sidecar->unit != unit.id) {
    return mismatch("unit", std::to_string(sidecar->unit), std::to_string(unit.id));
  }
  if (sidecar->shape_id != r.shape_id) {
    return mismatch("shape_id", std::to_string(sidecar->shape_id), std::to_string(r.shape_id));
  }
  if (sidecar->dir_id != r.dir_id) {
    return mismatch("dir_id", std::to_string(sidecar->dir_id), std::to_string(r.dir_id));
  }
  if (sidecar->resolution != ctx.plan.resolution) {
    return mismatch(
        "resolution", std::to_string(sidecar->resolution), std::to_string(ctx.plan.resolution));
  }
  if (!sidecar->hand_model_sha256.empty() &&
      sidecar->hand_model_sha256 != ctx.plan.hand_model_sha256) {
    return mismatch("hand_model_sha256", sidecar->hand_model_sha256, ctx.plan.hand_model_sha256);
  }
  auto image = ReadLabelExr(exr_path, ctx.exr_options);
  if (!image.ok()) return image.status();
  auto view = ConvertView(*image, *sidecar, ctx.view_options, exr_path.string());
  if (!view.ok()) return view.status();
  return ConvertedRender{
      std::move(view).value(), sidecar->blender_version, sidecar->script_version};
}

json JointPairsJson(const HandModel& hand) {
  json pairs = json::array();
  for (const auto& [a, b] : hand.joint_pairs) pairs.push_back({a, b});
  return pairs;
}

// What a shard's content depends on besides the render files themselves. A shard whose
// metadata carries the same key (and valid checksums) is kept on a rerun.
json ConversionKey(const RunContext& ctx, uint32_t unit_id, const ConvertOptions& options) {
  json edges_json = options.edges.ToJson();
  edges_json["joint_pairs"] = JointPairsJson(ctx.hand);
  json key = {
      {"unit", unit_id},
      {"plan_sha256", ctx.plan_sha256},
      {"tool_version", HANDDB_VERSION},
      {"edges", edges_json},
      {"normalisation",
       {{"diameter_px", kNormalisedDiameter},
        {"centre", "area centroid of the silhouette convex hull"},
        {"point_scale", kPointScale}}},
  };
  // Only when set, so the keys of plain shards (every database before v1.2) stay as they were.
  if (options.coded) key["coded"] = true;
  return key;
}

json HandModelJson(const HandModel& hand) {
  json limits = json::array();
  for (const HandDof& dof : hand.dofs) limits.push_back({dof.min, dof.max});
  return {{"name", hand.name}, {"sha256", hand.sha256}, {"joint_limits", limits}};
}

json LabelNamesJson(const HandModel& hand) {
  json dofs = json::array();
  for (const HandDof& dof : hand.dofs) dofs.push_back(dof.name);
  return {
      {"joint_angles", {{"names", dofs}, {"unit", "rad"}}},
      {"view_direction", {{"unit", "unit vector, hand frame, towards the camera"}}},
      {"view_theta", {{"unit", "rad"}}},
      {"view_phi", {{"unit", "rad"}}},
      {"camera_roll", {{"unit", "rad"}}},
      {"keypoints",
       {{"names", hand.keypoint_names},
        {"unit", "normalised px; x right, y down, z away from the camera from the look-at plane"}}},
      {"points",
       {{"unit", "1/16 normalised px"}, {"frame", "origin at the silhouette hull centroid"}}},
      {"source_diameter_px", {{"unit", "rendered px"}}},
      {"scale", {{"unit", "normalised px per rendered px"}}},
      {"source_centre_px", {{"unit", "rendered px"}}},
  };
}

json GenerationJson(const RunContext& ctx) {
  json gen = {{"seed", ctx.plan.seed},
              {"plan_sha256", ctx.plan_sha256},
              {"resolution", ctx.plan.resolution},
              {"ortho_scale", ctx.plan.ortho_scale},
              {"rolls", ctx.plan.rolls},
              {"unit_size", ctx.plan.unit_size}};
  gen["config"] = ctx.plan.doc.contains("config") ? ctx.plan.doc["config"] : json::object();
  return gen;
}

// Shape names by id (the query side shows them): [{id, name}].
json ShapesJson(const Plan& plan) {
  json shapes = json::array();
  for (const PlanShape& shape : plan.shapes) {
    shapes.push_back({{"id", shape.id}, {"name", shape.name}});
  }
  return shapes;
}

json SkippedJson(const std::vector<SkippedView>& skipped) {
  json out = json::array();
  for (const auto& s : skipped) {
    out.push_back({{"render_id", s.render_id}, {"file", s.file}, {"reason", s.reason}});
  }
  return out;
}

std::string JoinVersions(const std::set<std::string>& versions) {
  std::string out;
  for (const auto& v : versions) out += (out.empty() ? "" : ", ") + v;
  return out;
}

struct UnitState {
  const PlanUnit* unit = nullptr;
  fs::path shard_path;    // DB_DIR/shard-00007.hdb, where the unit's shard ends up
  fs::path staging_path;  // DB_DIR/shard-00007.next.hdb (docs/format.md section 8)
  // Where the unit's shard is (kept) or goes (written): shard_path, or staging_path while the
  // current manifest lists shard_path and so its bytes may not change.
  fs::path file;
  bool kept = false;
  json key;
  // Per render of the unit (checking pass).
  std::vector<std::optional<CanonicalView>> views;
  std::vector<bool> dropped;  // converted fine but not kept in memory
  std::vector<Status> errors;
  std::set<std::string> blender_versions;
  std::set<std::string> script_versions;
  std::vector<SkippedView> skipped;
  ManifestShard manifest_shard;
};

// A shard already in DB_DIR that is complete, intact and made from the same inputs with the
// same options. Fills the manifest entry and the skipped views it recorded.
bool KeepShardFile(UnitState* st, const fs::path& path, bool skip_bad) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return false;
  auto reader = ShardReader::Open(path);
  if (!reader.ok() || !reader->VerifyChecksums().ok()) return false;
  const json meta = json::parse(reader->metadata_json(), nullptr, /*allow_exceptions=*/false);
  if (!meta.is_object() || !meta.contains("conversion") || meta["conversion"] != st->key) {
    return false;
  }
  if (!meta.contains("skipped") || !meta["skipped"].is_array()) return false;
  if (!skip_bad && !meta["skipped"].empty()) return false;
  if (reader->num_views() + meta["skipped"].size() != st->unit->renders.size()) return false;
  for (const json& s : meta["skipped"]) {
    if (!s.is_object() || !s.contains("render_id") || !s["render_id"].is_number_unsigned() ||
        !s.contains("file") || !s["file"].is_string() || !s.contains("reason") ||
        !s["reason"].is_string()) {
      return false;
    }
    st->skipped.push_back({s["render_id"].get<uint32_t>(),
                           st->unit->id,
                           s["file"].get<std::string>(),
                           s["reason"].get<std::string>()});
  }
  const std::span<const uint8_t> bytes = reader->bytes();
  st->file = path;
  st->manifest_shard.file = path.filename().string();
  st->manifest_shard.views = reader->num_views();
  st->manifest_shard.points = reader->header().num_points;
  st->manifest_shard.bytes = bytes.size();
  st->manifest_shard.xxh3 = Hex64(XXH3_64bits(bytes.data(), bytes.size()));
  return true;
}

// The unit's shard under its own name or, left by a per-unit run or an interrupted rewrite, under
// its staging name.
bool KeepExistingShard(UnitState* st, bool skip_bad) {
  if (KeepShardFile(st, st->shard_path, skip_bad)) return true;
  st->skipped.clear();
  if (KeepShardFile(st, st->staging_path, skip_bad)) return true;
  st->skipped.clear();
  return false;
}

// Temp files a killed run left behind (base/atomic_file.h names them "<target>.tmp-*"): those
// of the shards this run writes and, when it writes the manifest, the manifest's. Nothing else in
// DB_DIR is touched.
void RemoveStaleTempFiles(const fs::path& db_dir,
                          const std::vector<UnitState>& units,
                          bool writes_manifest) {
  std::set<std::string> prefixes;
  for (const UnitState& st : units) {
    if (st.kept) continue;
    prefixes.insert(st.shard_path.filename().string() + ".tmp-");
    prefixes.insert(st.staging_path.filename().string() + ".tmp-");
  }
  if (writes_manifest) {
    prefixes.insert(std::string(kManifestFileName) + ".tmp-");
    prefixes.insert(std::string(kDatabaseHandModelFileName) + ".tmp-");
  }
  std::error_code ec;
  for (fs::directory_iterator it(db_dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const size_t dot = name.find(".tmp-");
    if (dot == std::string::npos) continue;
    if (prefixes.count(name.substr(0, dot + 5)) == 0) continue;
    std::error_code rm_ec;
    fs::remove(it->path(), rm_ec);  // best effort: a leftover temp file is harmless
  }
}

// The skipped-view record of a failed render: file relative to the render dir, reason without
// the path prefix (so shards do not depend on where the render dir is).
SkippedView MakeSkipped(const RunContext& ctx,
                        uint32_t unit,
                        uint32_t render_id,
                        const Status& status) {
  SkippedView s;
  s.render_id = render_id;
  s.unit = unit;
  s.file = RelativeRenderFile(unit, render_id, ".exr");
  std::string reason = status.message();
  for (const char* ext : {".exr", ".json"}) {
    const std::string prefix =
        (ctx.render_dir / RelativeRenderFile(unit, render_id, ext)).string() + ": ";
    if (reason.rfind(prefix, 0) == 0) {
      reason = reason.substr(prefix.size());
      s.file = RelativeRenderFile(unit, render_id, ext);
    }
  }
  s.reason = std::string(StatusCodeName(status.code())) + ": " + reason;
  return s;
}

}  // namespace

namespace {

// Step 1: the inputs every unit shares (plan, its hash, the hand model, the view conversion).
Result<RunContext> LoadRunContext(const fs::path& render_dir, const ConvertOptions& options) {
  RunContext ctx;
  ctx.render_dir = render_dir;
  const fs::path plan_path = render_dir / "plan.json";
  {
    auto plan = ReadPlan(plan_path);
    if (!plan.ok()) return plan.status();
    ctx.plan = std::move(plan).value();
    auto sha = Sha256File(plan_path);
    if (!sha.ok()) return sha.status();
    ctx.plan_sha256 = *sha;
  }
  {
    const fs::path hand_path = ResolvePlanPath(ctx.plan.hand_model_path);
    auto hand = LoadHandModel(hand_path);
    if (!hand.ok()) return hand.status();
    if (hand->sha256 != ctx.plan.hand_model_sha256) {
      return Status(StatusCode::kSizeMismatch,
                    hand_path.string() + ": hand model changed since the plan was made (sha256 " +
                        hand->sha256 + ", plan has " + ctx.plan.hand_model_sha256 + ")");
    }
    ctx.hand = std::move(hand).value();
  }
  ctx.view_options.edges = options.edges;
  ctx.view_options.joint_pairs = JointPairs();
  for (const auto& [a, b] : ctx.hand.joint_pairs) ctx.view_options.joint_pairs.Add(a, b);
  ctx.exr_options.expected_width = ctx.plan.resolution;
  ctx.exr_options.expected_height = ctx.plan.resolution;
  // Parallelism is across views; OpenEXR's own pool would only add hand-offs on small images.
  Imf::setGlobalThreadCount(0);

  return ctx;
}

// Step 2: the state of every unit of the plan; `selected` marks the units this run converts
// (options.units, or all). Unless `check_only`, a selected unit must be completely rendered.
Result<std::vector<UnitState>> PrepareUnits(const RunContext& ctx,
                                            const fs::path& db_dir,
                                            const ConvertOptions& options,
                                            bool check_only,
                                            std::vector<bool>* selected_out) {
  const fs::path plan_path = ctx.render_dir / "plan.json";
  std::vector<UnitState> units(ctx.plan.units.size());
  std::vector<bool> selected(units.size(), options.units.empty());
  for (uint32_t id : options.units) {
    if (id >= units.size()) {
      return Status(StatusCode::kOutOfRange,
                    plan_path.string() + ": no unit " + std::to_string(id) + " (the plan has " +
                        std::to_string(units.size()) + ")");
    }
    selected[id] = true;
  }
  for (size_t u = 0; u < units.size(); ++u) {
    UnitState& st = units[u];
    st.unit = &ctx.plan.units[u];
    st.shard_path = db_dir / ShardFileName(st.unit->id);
    st.staging_path = db_dir / ShardStagingFileName(st.unit->id);
    st.key = ConversionKey(ctx, st.unit->id, options);
    if (!selected[u] || check_only) continue;
    const fs::path unit_dir = ctx.render_dir / "units" / UnitDirName(st.unit->id);
    std::error_code ec;
    if (!fs::exists(unit_dir / "DONE", ec)) {
      return Status(StatusCode::kNotFound,
                    unit_dir.string() +
                        ": render unit is incomplete (no DONE marker); render it "
                        "first (handdb render)");
    }
  }

  *selected_out = std::move(selected);
  return units;
}

// Step 4: convert every view of the units to (re)write, keeping results in memory up to the
// budget; a bad view's error is kept in its unit's state.
Status CheckViews(const RunContext& ctx,
                  std::vector<UnitState>& units,
                  const ConvertOptions& options,
                  int threads) {
  struct Task {
    size_t unit;
    size_t render;
  };
  std::vector<Task> tasks;
  for (size_t u = 0; u < units.size(); ++u) {
    UnitState& st = units[u];
    if (st.kept) continue;
    const size_t n = st.unit->renders.size();
    st.views.resize(n);
    st.dropped.assign(n, false);
    st.errors.resize(n);
    for (size_t r = 0; r < n; ++r) tasks.push_back({u, r});
  }
  std::atomic<uint64_t> memory{0};
  std::mutex version_mu;
  {
    Progress progress("convert", tasks.size(), options.progress, "views");
    HANDDB_RETURN_IF_ERROR(ParallelForStatus(tasks.size(), threads, options.cancel, [&](size_t t) {
      UnitState& st = units[tasks[t].unit];
      const size_t r = tasks[t].render;
      auto converted = ConvertRender(ctx, *st.unit, st.unit->renders[r]);
      if (!converted.ok()) {
        st.errors[r] = converted.status();
      } else {
        {
          std::lock_guard<std::mutex> lock(version_mu);
          st.blender_versions.insert(converted->blender_version);
          if (!converted->script_version.empty())
            st.script_versions.insert(converted->script_version);
        }
        const uint64_t bytes = converted->view.points.size() * sizeof(PointQ) + sizeof(ViewLabel);
        if (memory.fetch_add(bytes) + bytes <= options.memory_budget_bytes) {
          st.views[r] = std::move(converted->view);
        } else {
          st.dropped[r] = true;
        }
      }
      progress.Add();
      return Status::Ok();
    }));
  }

  return Status::Ok();
}

// Step 5: every bad view as a skipped-view record (also into *bad when given); without
// skip_bad any bad view is the error.
Status CollectBadViews(const RunContext& ctx,
                       std::vector<UnitState>& units,
                       const ConvertOptions& options,
                       std::vector<SkippedView>* bad) {
  std::vector<SkippedView> all_bad;
  Status first_bad;
  for (UnitState& st : units) {
    if (st.kept) continue;
    for (size_t r = 0; r < st.errors.size(); ++r) {
      if (st.errors[r].ok()) continue;
      if (first_bad.ok()) first_bad = st.errors[r];
      SkippedView s = MakeSkipped(ctx, st.unit->id, st.unit->renders[r].render_id, st.errors[r]);
      st.skipped.push_back(s);
      all_bad.push_back(std::move(s));
    }
  }
  if (bad != nullptr) *bad = all_bad;
  if (!all_bad.empty() && !options.skip_bad) {
    std::string msg = first_bad.message();
    if (all_bad.size() > 1)
      msg += " (and " + std::to_string(all_bad.size() - 1) + " more bad views)";
    return Status(first_bad.code(),
                  msg + "; nothing written (use --skip-bad to leave bad views out)");
  }

  return Status::Ok();
}

// Step 6: write the shards of the units not kept.
Status WriteShards(const RunContext& ctx,
                   const fs::path& db_dir,
                   std::vector<UnitState>& units,
                   const ConvertOptions& options,
                   int threads) {
  // Writing pass. The current manifest stays in place and no file it lists is touched, so a
  // query meanwhile reads the old database whole (docs/format.md section 8). While a manifest is
  // in place every new shard goes to its staging name, unless the manifest lists that name (an
  // interrupted rewrite): then the plain name is the one no reader uses.
  std::error_code ec;
  fs::create_directories(db_dir, ec);
  if (ec) return Status(StatusCode::kIoError, db_dir.string() + ": cannot create: " + ec.message());
  std::set<std::string> listed;
  const Result<Manifest> current = ReadManifest(db_dir);
  if (current.ok()) {
    for (const ManifestShard& s : current->shards) listed.insert(s.file);
  }
  std::vector<size_t> to_write;
  for (size_t u = 0; u < units.size(); ++u) {
    UnitState& st = units[u];
    if (st.kept) continue;
    to_write.push_back(u);
    const bool staged = current.ok() && listed.count(st.staging_path.filename().string()) == 0;
    st.file = staged ? st.staging_path : st.shard_path;
  }
  RemoveStaleTempFiles(db_dir, units, options.units.empty());
  const json generation = GenerationJson(ctx);
  const json hand_json = HandModelJson(ctx.hand);
  const json label_names = LabelNamesJson(ctx.hand);
  const json shapes = ShapesJson(ctx.plan);
  HANDDB_RETURN_IF_ERROR(ParallelForStatus(to_write.size(), threads, options.cancel, [&](size_t i) {
    UnitState& st = units[to_write[i]];
    json meta = {{"format", "handdb-shard-metadata"},
                 {"version", kShardMetadataVersion},
                 {"unit", st.unit->id},
                 {"conversion", st.key},
                 {"generation", generation},
                 {"hand_model", hand_json},
                 {"tool", {{"name", "handdb"}, {"version", HANDDB_VERSION}}},
                 {"blender_version", JoinVersions(st.blender_versions)},
                 {"script_version", JoinVersions(st.script_versions)},
                 {"rolls", ctx.plan.rolls},
                 {"labels", label_names},
                 {"shapes", shapes},
                 {"skipped", SkippedJson(st.skipped)}};
    ShardWriterOptions wopt;
    wopt.metadata_json = meta.dump();
    wopt.coded = options.coded;
    ShardWriter writer;
    HANDDB_RETURN_IF_ERROR(writer.Open(st.file, wopt));
    for (size_t r = 0; r < st.errors.size(); ++r) {
      if (!st.errors[r].ok()) continue;
      if (st.dropped[r]) {
        auto again = ConvertRender(ctx, *st.unit, st.unit->renders[r]);
        if (!again.ok()) return again.status();  // the file changed since the checking pass
        HANDDB_RETURN_IF_ERROR(writer.AddView(again->view.label, again->view.points));
      } else {
        HANDDB_RETURN_IF_ERROR(writer.AddView(st.views[r]->label, st.views[r]->points));
        st.views[r].reset();
      }
    }
    auto summary = writer.Finish();
    if (!summary.ok()) return summary.status();
    st.manifest_shard.file = st.file.filename().string();
    st.manifest_shard.views = summary->num_views;
    st.manifest_shard.points = summary->num_points;
    st.manifest_shard.bytes = summary->file_size;
    st.manifest_shard.xxh3 = summary->checksum;
    return Status::Ok();
  }));

  return Status::Ok();
}

// `to` (not listed by the current manifest) becomes a second name of `from`'s bytes, atomically:
// a hard link renamed over it, or a copy where the filesystem has no hard links.
Status ReplaceWithLink(const fs::path& from, const fs::path& to) {
  const fs::path temp = to.string() + ".tmp-link";  // a stale one is removed like any temp file
  std::error_code ec;
  fs::remove(temp, ec);
  if (::link(from.c_str(), temp.c_str()) != 0) {
    AtomicFileWriter copy;
    HANDDB_RETURN_IF_ERROR(copy.Open(to));
    Result<std::string> bytes = ReadFileToString(from);
    if (!bytes.ok()) return bytes.status();
    HANDDB_RETURN_IF_ERROR(copy.Write(*bytes));
    return copy.Commit();
  }
  if (::rename(temp.c_str(), to.c_str()) != 0) {
    const int err = errno;
    fs::remove(temp, ec);
    return Status(StatusCode::kIoError,
                  to.string() + ": cannot rename " + temp.filename().string() +
                      " over it: " + std::strerror(err));
  }
  return Status::Ok();
}

// Puts `manifest` (every unit's shard under UnitState::file) in place so that at every moment
// the manifest.json a reader finds lists complete files with exactly the listed bytes
// (docs/format.md section 8):
//   1. a manifest naming the staging files of the units that have them (the old manifest's files
//      are untouched up to here);
//   2. each plain name replaced by a hard link to its staging file (no manifest lists the plain
//      name now);
//   3. the final manifest, plain names only: byte for byte what a fresh convert writes;
//   4. the staging files removed (no manifest lists them now).
// A crash between any two steps leaves a complete database; the next convert finishes the job.
Status SwapInManifest(const fs::path& db_dir, std::vector<UnitState>& units, Manifest* manifest) {
  std::vector<size_t> staged;
  for (size_t u = 0; u < units.size(); ++u) {
    if (units[u].file == units[u].staging_path) staged.push_back(u);
  }
  if (!staged.empty()) {
    HANDDB_RETURN_IF_ERROR(WriteManifest(db_dir, *manifest));
    for (size_t u : staged) {
      HANDDB_RETURN_IF_ERROR(ReplaceWithLink(units[u].staging_path, units[u].shard_path));
    }
    HANDDB_RETURN_IF_ERROR(SyncDirectory(db_dir));
    for (ManifestShard& entry : manifest->shards) entry.file = ShardFinalFileName(entry.file);
  }
  HANDDB_RETURN_IF_ERROR(WriteManifest(db_dir, *manifest));
  // Staging files of this run and ones an interrupted run left: best effort, a leftover is
  // unlisted and harmless (validate ignores it, the next convert removes it).
  bool removed = false;
  for (UnitState& st : units) {
    std::error_code ec;
    removed |= fs::remove(st.staging_path, ec);
    st.file = st.shard_path;
  }
  if (removed) return SyncDirectory(db_dir);
  return Status::Ok();
}

// DB_DIR/hand_model.json: the bytes of the hand model the views were made with, so the database
// carries its rig (generator/hand/database_rig.h). The bytes written are the ones hashed here,
// and must hash to what the shards record.
Status WriteHandModelCopy(const RunContext& ctx, const fs::path& db_dir) {
  Result<std::string> bytes = ReadFileToString(ctx.hand.path);
  if (!bytes.ok()) return bytes.status();
  const std::string sha = Sha256Hex(*bytes);
  if (sha != ctx.hand.sha256) {
    return Status(StatusCode::kChecksumMismatch,
                  ctx.hand.path.string() + ": hand model changed during the convert (sha256 " +
                      sha + ", was " + ctx.hand.sha256 + ")");
  }
  return WriteFileAtomic(db_dir / kDatabaseHandModelFileName, *bytes);
}

// Step 7: the summary of the selected units and, for a run over all units, the manifest.
Result<ConvertSummary> FinishRun(const RunContext& ctx,
                                 const fs::path& db_dir,
                                 std::vector<UnitState>& units,
                                 const std::vector<bool>& selected,
                                 const ConvertOptions& options) {
  const json generation = GenerationJson(ctx);
  const json hand_json = HandModelJson(ctx.hand);
  const json label_names = LabelNamesJson(ctx.hand);
  const json shapes = ShapesJson(ctx.plan);
  // The manifest, last: exactly the complete shards, in unit order.
  Manifest manifest;
  manifest.tool_version = HANDDB_VERSION;
  manifest.rolls = static_cast<uint32_t>(ctx.plan.rolls);
  manifest.metadata = {
      {"generation", generation},
      {"hand_model", hand_json},
      {"conversion",
       {{"edges", units.empty() ? json() : units[0].key["edges"]},
        {"normalisation", units.empty() ? json() : units[0].key["normalisation"]}}},
      {"labels", label_names},
      {"shapes", shapes}};
  ConvertSummary summary;
  summary.units_total =
      static_cast<uint32_t>(options.units.empty() ? units.size() : options.units.size());
  summary.rolls = manifest.rolls;
  for (size_t u = 0; u < units.size(); ++u) {
    if (!selected[u]) continue;
    UnitState& st = units[u];
    manifest.shards.push_back(st.manifest_shard);
    (st.kept ? summary.shards_kept : summary.shards_written)++;
    summary.views += st.manifest_shard.views;
    summary.points += st.manifest_shard.points;
    summary.bytes += st.manifest_shard.bytes;
    for (const SkippedView& s : st.skipped) {
      manifest.skipped.push_back({s.render_id, s.file, s.reason});
      summary.skipped.push_back(s);
    }
  }
  manifest.UpdateTotals();
  // The manifest lists every shard: only a run over all units writes it, after the hand model
  // copy it vouches for (its sha256 is the manifest's hand_model.sha256).
  if (options.units.empty()) {
    HANDDB_RETURN_IF_ERROR(WriteHandModelCopy(ctx, db_dir));
    HANDDB_RETURN_IF_ERROR(SwapInManifest(db_dir, units, &manifest));
  }
  return summary;
}

// ConvertRenderDir, or with `complete` only the check which shards would be kept.
Result<ConvertSummary> ConvertOrCheck(const fs::path& render_dir,
                                      const fs::path& db_dir,
                                      const ConvertOptions& options,
                                      std::vector<SkippedView>* bad,
                                      std::vector<bool>* complete) {
  THROW_CHECK(options.Check());
  const auto start = std::chrono::steady_clock::now();
  const int threads = ResolveNumThreads(options.num_threads);
  Result<RunContext> context = LoadRunContext(render_dir, options);
  if (!context.ok()) return context.status();
  const RunContext& ctx = *context;
  std::vector<bool> selected;
  Result<std::vector<UnitState>> prepared =
      PrepareUnits(ctx, db_dir, options, complete != nullptr, &selected);
  if (!prepared.ok()) return prepared.status();
  std::vector<UnitState>& units = *prepared;

  // Step 3: shards already done on an earlier run.
  HANDDB_RETURN_IF_ERROR(ParallelForStatus(units.size(), threads, options.cancel, [&](size_t u) {
    if (selected[u]) units[u].kept = KeepExistingShard(&units[u], options.skip_bad);
    return Status::Ok();
  }));
  if (complete != nullptr) {
    complete->assign(units.size(), false);
    for (size_t u = 0; u < units.size(); ++u) (*complete)[u] = units[u].kept;
    return ConvertSummary{};
  }
  // Units outside options.units are left as they are.
  for (size_t u = 0; u < units.size(); ++u) {
    if (!selected[u]) units[u].kept = true;
  }
  HANDDB_RETURN_IF_ERROR(CheckViews(ctx, units, options, threads));
  HANDDB_RETURN_IF_ERROR(CollectBadViews(ctx, units, options, bad));
  HANDDB_RETURN_IF_ERROR(WriteShards(ctx, db_dir, units, options, threads));
  Result<ConvertSummary> summary = FinishRun(ctx, db_dir, units, selected, options);
  if (!summary.ok()) return summary.status();
  summary->seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace

Result<ConvertSummary> ConvertRenderDir(const fs::path& render_dir,
                                        const fs::path& db_dir,
                                        const ConvertOptions& options,
                                        std::vector<SkippedView>* bad) {
  return ConvertOrCheck(render_dir, db_dir, options, bad, nullptr);
}

Result<std::vector<bool>> FindCompleteShards(const fs::path& render_dir,
                                             const fs::path& db_dir,
                                             const ConvertOptions& options) {
  std::vector<bool> complete;
  auto checked = ConvertOrCheck(render_dir, db_dir, options, nullptr, &complete);
  if (!checked.ok()) return checked.status();
  return complete;
}

}  // namespace handdb
