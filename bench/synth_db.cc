// Synthetic databases for the index's scaling measurements: N canonical views made from a real
// database's views without Blender, so that 10M and 50M virtual views can be built in minutes.
//
//   synth_db --from DB --out DIR --views N [--per-shard 4096] [--seed 1] [--threads 2] [--coded]
//
// View i copies source view i mod |DB| (label included, render_id set to i) with its edge points
// moved by a random similarity close to the identity (scale 0.96-1.04, rotation +-3 degrees,
// shift +-2 px), each point jittered by +-0.6 px and 5% of them dropped: near-copies at D_c ~ 1-3
// px of their source, so the database has the density of a real one sampled finely, not exact
// duplicates. Deterministic from the seed for any --threads. The shards are written with the
// project's writer (coarse fields included), each with the source's shard metadata (its unit
// number replaced), and the manifest records {"synthetic": {...}} beside the source's metadata;
// `handdb validate` and `handdb index` work on the result like on any database.
// --coded writes coded shards (format v1.2, docs/format.md section 10) and snaps every warped
// point back onto its source view's render lattice (the pixel it falls in, normalised with the
// view's record), unique and sorted, as a converted view's points are: so the synthetic views
// take the lattice code, as real ones do, instead of the raw fallback.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "base/progress.h"
#include "base/thread_pool.h"
#include "edges/normalise.h"
#include "format/manifest.h"
#include "format/shard_reader.h"
#include "format/shard_writer.h"
#include "handdb_version.h"
#include "query/database.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace handdb {
namespace {

struct Args {
  std::string from, out;
  uint64_t views = 0;
  uint64_t per_shard = 4096;
  uint32_t seed = 1;
  int threads = 2;
  bool coded = false;
};

[[noreturn]] void Usage(const std::string& problem) {
  std::fprintf(stderr,
               "synth_db: %s\nusage: synth_db --from DB --out DIR --views N [--per-shard 4096] "
               "[--seed 1] [--threads 2] [--coded]\n",
               problem.c_str());
  std::exit(2);
}

Args Parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) Usage(k + " needs a value");
      return argv[++i];
    };
    if (k == "--from")
      a.from = next();
    else if (k == "--out")
      a.out = next();
    else if (k == "--views")
      a.views = std::stoull(next());
    else if (k == "--per-shard")
      a.per_shard = std::stoull(next());
    else if (k == "--seed")
      a.seed = static_cast<uint32_t>(std::stoul(next()));
    else if (k == "--threads")
      a.threads = std::stoi(next());
    else if (k == "--coded")
      a.coded = true;
    else
      Usage("unknown argument " + k);
  }
  if (a.from.empty() || a.out.empty() || a.views == 0 || a.per_shard == 0) {
    Usage("--from, --out and --views are required");
  }
  return a;
}

std::vector<PointQ> Warp(std::span<const PointQ> src, uint32_t seed, uint64_t view) {
  std::seed_seq seq{seed, static_cast<uint32_t>(view), static_cast<uint32_t>(view >> 32)};
  std::mt19937 rng(seq);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const double scale = 1.0 + 0.04 * unit(rng);
  const double angle = 3.0 * M_PI / 180.0 * unit(rng);
  const double tx = 2.0 * kPointScale * unit(rng), ty = 2.0 * kPointScale * unit(rng);
  const double c = scale * std::cos(angle), s = scale * std::sin(angle);
  std::vector<PointQ> out;
  out.reserve(src.size());
  for (const PointQ& p : src) {
    const double jx = 0.6 * kPointScale * unit(rng), jy = 0.6 * kPointScale * unit(rng);
    if (rng() % 20 == 0) continue;
    const double x = c * p.x - s * p.y + tx + jx;
    const double y = s * p.x + c * p.y + ty + jy;
    auto q = [](double v) {
      return static_cast<int16_t>(std::clamp(std::lround(v), -6144L, 6144L));
    };
    out.push_back({q(x), q(y)});
  }
  if (out.empty()) out.push_back(src.front());
  return out;
}

// The points of the render pixels `pts` fall in, normalised as the converter does
// (edges/normalise.h: unique, sorted by (y, x)) with the label's float scale and centre, which
// is what the point code's decoder uses (format/point_codec.cc); points beyond the shard's
// range are dropped.
std::vector<PointQ> SnapToLattice(const std::vector<PointQ>& pts, const ViewLabel& label) {
  Normalisation norm;
  norm.scale = label.scale;
  norm.centre_x = label.source_centre_px[0];
  norm.centre_y = label.source_centre_px[1];
  const double s = norm.scale * kPointScale;
  std::vector<EdgePixel> pixels;
  pixels.reserve(pts.size());
  for (const PointQ& p : pts) {
    const double col = std::nearbyint(p.x / s + norm.centre_x - 0.5);
    const double row = std::nearbyint(p.y / s + norm.centre_y - 0.5);
    // 8 px of margin: whatever rounds back inside the range is kept, nothing overflows int16.
    if (std::fabs((col + 0.5 - norm.centre_x) * s) > 6144 + 8 * s ||
        std::fabs((row + 0.5 - norm.centre_y) * s) > 6144 + 8 * s) {
      continue;
    }
    pixels.push_back({static_cast<int32_t>(col), static_cast<int32_t>(row)});
  }
  std::vector<PointQ> out = NormalisePixels(pixels, norm);
  std::erase_if(out, [](const PointQ& p) { return std::abs(p.x) > 6144 || std::abs(p.y) > 6144; });
  return out;
}

std::string ShardName(uint64_t unit) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "shard-%05llu.hdb", static_cast<unsigned long long>(unit));
  return buf;
}

int Main(int argc, char** argv) {
  Args args;
  try {
    args = Parse(argc, argv);
  } catch (const std::exception&) {  // std::stoull and friends on a malformed number
    Usage("a number argument is not a number");
  }
  auto db = Database::Open(args.from);
  if (!db.ok()) {
    std::fprintf(stderr, "synth_db: %s\n", db.status().ToString().c_str());
    return 1;
  }
  const Manifest& source = db->manifest();
  auto first = ShardReader::Open(fs::path(args.from) / source.shards.front().file);
  if (!first.ok()) {
    std::fprintf(stderr, "synth_db: %s\n", first.status().ToString().c_str());
    return 1;
  }
  const json source_meta = json::parse(first->metadata_json());
  std::error_code ec;
  fs::create_directories(args.out, ec);
  if (fs::exists(fs::path(args.out) / "manifest.json")) {
    std::fprintf(stderr, "synth_db: %s already holds a database\n", args.out.c_str());
    return 1;
  }
  const uint64_t shards = (args.views + args.per_shard - 1) / args.per_shard;
  const size_t n_src = db->num_views();
  std::vector<ShardSummary> summaries(shards);
  Progress progress("synth", shards, true, "shards");
  const Status st = ParallelForStatus(shards, args.threads, nullptr, [&](size_t u) -> Status {
    json meta = source_meta;
    meta["unit"] = u;
    meta["skipped"] = json::array();
    ShardWriterOptions wopt;
    wopt.metadata_json = meta.dump();
    wopt.coded = args.coded;
    ShardWriter writer;
    HANDDB_RETURN_IF_ERROR(writer.Open(fs::path(args.out) / ShardName(u), wopt));
    const uint64_t begin = u * args.per_shard;
    const uint64_t end = std::min(args.views, begin + args.per_shard);
    for (uint64_t i = begin; i < end; ++i) {
      const auto v = static_cast<view_id_t>(i % n_src);
      ViewLabel label = db->label(v);
      label.render_id = static_cast<render_id_t>(i);
      std::vector<PointQ> pts = Warp(db->points(v), args.seed, i);
      if (args.coded && label.scale > 0) pts = SnapToLattice(pts, label);
      HANDDB_RETURN_IF_ERROR(writer.AddView(label, pts));
    }
    auto done = writer.Finish();
    if (!done.ok()) return done.status();
    summaries[u] = *done;
    progress.Add();
    return Status::Ok();
  });
  if (!st.ok()) {
    std::fprintf(stderr, "synth_db: %s\n", st.ToString().c_str());
    return 1;
  }
  Manifest m;
  m.tool_version = HANDDB_VERSION;
  m.rolls = source.rolls;
  m.metadata = source.metadata;
  m.metadata["synthetic"] = {{"source", fs::absolute(args.from).string()},
                             {"source_views", n_src},
                             {"seed", args.seed},
                             {"warp",
                              "similarity: scale 0.96-1.04, rotation +-3 deg, shift +-2 px; "
                              "jitter +-0.6 px; 5% of points dropped"},
                             {"coded", args.coded}};
  if (args.coded) {
    m.metadata["synthetic"]["lattice"] =
        "points snapped to their source view's render pixels, unique, sorted";
  }
  for (const ShardSummary& s : summaries) m.AddShard(s);
  const Status w = WriteManifest(args.out, m);
  if (!w.ok()) {
    std::fprintf(stderr, "synth_db: %s\n", w.ToString().c_str());
    return 1;
  }
  uint64_t bytes = 0, points = 0;
  for (const ShardSummary& s : summaries) {
    bytes += s.file_size;
    points += s.num_points;
  }
  std::printf(
      "synth_db: %s: %llu canonical views (%llu virtual) in %llu shards, %llu points, "
      "%.1f MB (%.1f B per virtual view)\n",
      args.out.c_str(),
      static_cast<unsigned long long>(args.views),
      static_cast<unsigned long long>(args.views * m.rolls),
      static_cast<unsigned long long>(shards),
      static_cast<unsigned long long>(points),
      bytes / 1e6,
      static_cast<double>(bytes) / static_cast<double>(args.views * m.rolls));
  return 0;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) { return handdb::Main(argc, argv); }
