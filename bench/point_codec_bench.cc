// Point compression benchmark: how small a real database's points get with the
// lattice chain code (format/point_codec.h), and how fast the refine stage could decode them.
//
//   point_codec_bench --db DB_DIR [--reps 5] [--max-views N]
//
// For every view: its edge pixels are recovered from the stored points and the label's
// normalisation (pixel = round(point / (16 scale) + centre - 1/2)), re-normalised to check they
// give the stored points back (the codec is lossless only for views on the render lattice:
// converted views are, synthetic benchmark views jittered off it are not), encoded, decoded and
// compared. Prints bytes per point and per view against PointQ's 4 bytes, decode time per view
// (median of --reps passes over all views), the symbol counts and the canonical Huffman code
// lengths they imply (format/point_codec.cc's table); the same for the coarse fields with
// format/field_codec.h; and the database's bytes per canonical and per virtual view today, with
// coded points, and with coded points and fields.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <queue>
#include <string>
#include <vector>

#include "format/coarse_field.h"
#include "format/field_codec.h"
#include "format/point_codec.h"
#include "query/database.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

std::span<const uint8_t> Bytes(const std::string& s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Canonical Huffman code lengths of `counts` (a zero count gets a count of one: every symbol
// must stay codable), by the textbook merge of the two lightest subtrees.
std::vector<int> HuffmanLengths(const uint64_t* counts, int n) {
  struct Node {
    uint64_t weight;
    int id;
  };
  auto heavier = [](const Node& a, const Node& b) {
    return a.weight != b.weight ? a.weight > b.weight : a.id > b.id;
  };
  std::priority_queue<Node, std::vector<Node>, decltype(heavier)> heap(heavier);
  std::vector<int> parent(2 * n, -1);
  for (int i = 0; i < n; ++i) heap.push({std::max<uint64_t>(counts[i], 1), i});
  int next = n;
  while (heap.size() > 1) {
    const Node a = heap.top();
    heap.pop();
    const Node b = heap.top();
    heap.pop();
    parent[a.id] = parent[b.id] = next;
    heap.push({a.weight + b.weight, next++});
  }
  std::vector<int> lengths(n, 0);
  for (int i = 0; i < n; ++i) {
    for (int p = parent[i]; p != -1; p = parent[p]) ++lengths[i];
  }
  return lengths;
}

int Run(int argc, char** argv) {
  fs::path db_dir;
  int reps = 5;
  size_t max_views = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "point_codec_bench: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--db") {
      db_dir = value();
    } else if (a == "--reps") {
      reps = std::max(1, std::atoi(value().c_str()));
    } else if (a == "--max-views") {
      max_views = static_cast<size_t>(std::atoll(value().c_str()));
    } else {
      std::fprintf(stderr, "usage: point_codec_bench --db DB_DIR [--reps 5] [--max-views N]\n");
      return 2;
    }
  }
  if (db_dir.empty()) {
    std::fprintf(stderr, "point_codec_bench: --db DB_DIR is required\n");
    return 2;
  }
  Result<Database> opened = Database::Open(db_dir);
  if (!opened.ok()) {
    std::fprintf(stderr, "point_codec_bench: %s\n", opened.status().ToString().c_str());
    return 1;
  }
  const Database& db = *opened;
  size_t n = db.num_views();
  if (max_views > 0) n = std::min(n, max_views);

  // A view's edge pixels, from its points and normalisation; `exact` / `near` count points the
  // pixels reproduce exactly / within one 1/16 px unit (the label keeps the normalisation in
  // float, the converter used double).
  auto recover =
      [&](size_t v, std::vector<LatticePixel>* pixels, uint64_t* inexact, uint64_t* far) {
        const ViewLabel label = db.label(static_cast<view_id_t>(v));
        const double s = static_cast<double>(label.scale) * kPointScale;
        const double cx = label.source_centre_px[0], cy = label.source_centre_px[1];
        pixels->clear();
        for (const PointQ& p : db.points(static_cast<view_id_t>(v))) {
          const LatticePixel q{static_cast<int32_t>(std::lround(p.x / s + cx - 0.5)),
                               static_cast<int32_t>(std::lround(p.y / s + cy - 0.5))};
          const double dx = std::fabs(std::nearbyint((q.col + 0.5 - cx) * s) - p.x);
          const double dy = std::fabs(std::nearbyint((q.row + 0.5 - cy) * s) - p.y);
          *inexact += dx > 0 || dy > 0;
          *far += dx > 1 || dy > 1;
          pixels->push_back(q);
        }
        std::sort(pixels->begin(), pixels->end(), [](const LatticePixel& a, const LatticePixel& b) {
          return a.row != b.row ? a.row < b.row : a.col < b.col;
        });
      };

  // Recover, check, encode.
  std::vector<std::string> codes(n);
  LatticeCodeStats stats;
  uint64_t points = 0, inexact_points = 0, far_points = 0, far_views = 0, merged = 0;
  std::vector<LatticePixel> pixels, back;
  double encode_seconds = 0;
  for (size_t v = 0; v < n; ++v) {
    points += db.points(static_cast<view_id_t>(v)).size();
    uint64_t far = 0;
    recover(v, &pixels, &inexact_points, &far);
    far_points += far;
    far_views += far > 0;
    const size_t before = pixels.size();
    pixels.erase(std::unique(pixels.begin(), pixels.end()), pixels.end());
    merged += before - pixels.size();
    const double t0 = Now();
    const Status st = EncodeLatticePixels(pixels, &codes[v], &stats);
    encode_seconds += Now() - t0;
    if (!st.ok()) {
      std::fprintf(stderr, "point_codec_bench: view %zu: %s\n", v, st.ToString().c_str());
      return 1;
    }
  }
  // Decode every view and compare with its pixels.
  uint64_t mismatched = 0;
  for (size_t v = 0; v < n; ++v) {
    const Status st = DecodeLatticePixels(
        {reinterpret_cast<const uint8_t*>(codes[v].data()), codes[v].size()}, &back);
    if (!st.ok()) {
      std::fprintf(stderr, "point_codec_bench: view %zu: %s\n", v, st.ToString().c_str());
      return 1;
    }
    uint64_t ignored = 0;
    recover(v, &pixels, &ignored, &ignored);
    pixels.erase(std::unique(pixels.begin(), pixels.end()), pixels.end());
    mismatched += back != pixels;
  }
  std::vector<double> decode_us, normalise_us;
  std::vector<PointQ> q;
  uint64_t sink = 0;
  for (int r = 0; r < reps; ++r) {
    double dec = 0, norm = 0;
    for (size_t v = 0; v < n; ++v) {
      const double t0 = Now();
      (void)DecodeLatticePixels(
          {reinterpret_cast<const uint8_t*>(codes[v].data()), codes[v].size()}, &back);
      const double t1 = Now();
      // To points as the converter makes them (raster order is already (y, x) order).
      const ViewLabel label = db.label(static_cast<view_id_t>(v));
      const double s = static_cast<double>(label.scale) * kPointScale;
      const double cx = label.source_centre_px[0], cy = label.source_centre_px[1];
      q.clear();
      for (const LatticePixel& p : back) {
        q.push_back({static_cast<int16_t>(std::nearbyint((p.col + 0.5 - cx) * s)),
                     static_cast<int16_t>(std::nearbyint((p.row + 0.5 - cy) * s))});
      }
      const double t2 = Now();
      sink += q.size();
      dec += t1 - t0;
      norm += t2 - t1;
    }
    decode_us.push_back(1e6 * dec / n);
    normalise_us.push_back(1e6 * norm / n);
  }
  std::sort(decode_us.begin(), decode_us.end());
  std::sort(normalise_us.begin(), normalise_us.end());

  // What a shard would store: the exact code of each view's PointQ (format/point_codec.h
  // EncodeViewPoints: the lattice code plus corrections, or raw), checked and timed.
  uint64_t view_bytes = 0, view_lattice = 0, view_raw = 0, view_mismatched = 0;
  std::vector<double> view_decode_us;
  {
    std::vector<std::string> view_codes(n);
    std::vector<ViewLabel> labels(n);
    std::vector<PointQ> decoded;
    for (size_t v = 0; v < n; ++v) {
      labels[v] = db.label(static_cast<view_id_t>(v));
      const std::span<const PointQ> pts = db.points(static_cast<view_id_t>(v));
      int mode = -1;
      const Status st =
          EncodeViewPoints(pts, labels[v].scale, labels[v].source_centre_px, &view_codes[v], &mode);
      if (!st.ok()) {
        std::fprintf(stderr, "point_codec_bench: view %zu: %s\n", v, st.ToString().c_str());
        return 1;
      }
      view_bytes += view_codes[v].size();
      (mode == 0 ? view_lattice : view_raw) += 1;
      const Status d = DecodeViewPoints(
          Bytes(view_codes[v]), labels[v].scale, labels[v].source_centre_px, &decoded);
      view_mismatched +=
          !d.ok() || decoded.size() != pts.size() ||
          !std::equal(
              decoded.begin(), decoded.end(), pts.begin(), [](const PointQ& a, const PointQ& b) {
                return a.x == b.x && a.y == b.y;
              });
    }
    for (int r = 0; r < reps; ++r) {
      const double t0 = Now();
      for (size_t v = 0; v < n; ++v) {
        (void)DecodeViewPoints(
            Bytes(view_codes[v]), labels[v].scale, labels[v].source_centre_px, &decoded);
      }
      view_decode_us.push_back(1e6 * (Now() - t0) / static_cast<double>(n));
    }
    std::sort(view_decode_us.begin(), view_decode_us.end());
  }

  uint64_t coded = 0;
  std::vector<size_t> sizes;
  for (const std::string& c : codes) {
    coded += c.size();
    sizes.push_back(c.size());
  }
  std::sort(sizes.begin(), sizes.end());
  uint64_t shard_bytes = 0, index_bytes = 0;
  for (const auto& e : fs::directory_iterator(db_dir)) {
    if (!e.is_regular_file()) continue;
    const std::string ext = e.path().extension().string();
    if (ext == ".hdb") shard_bytes += e.file_size();
    if (ext == ".hdbi") index_bytes += e.file_size();
  }
  const double rolls = db.num_rolls();
  const double views = static_cast<double>(db.num_views());
  const double pointq_per_view = 4.0 * static_cast<double>(points) / static_cast<double>(n);
  const double coded_per_view = static_cast<double>(coded) / static_cast<double>(n);
  const double shards_per_view = static_cast<double>(shard_bytes) / views;
  const double index_per_view = static_cast<double>(index_bytes) / views;
  const double view_per_view = static_cast<double>(view_bytes) / static_cast<double>(n);
  const double with_code = shards_per_view - pointq_per_view + view_per_view;

  std::printf("point_codec_bench: %s, %zu of %zu views, %.1f points/view, %d rolls\n",
              db_dir.c_str(),
              n,
              db.num_views(),
              static_cast<double>(points) / n,
              db.num_rolls());
  std::printf(
      "  lattice check: %llu points not reproduced exactly by their pixels and the "
      "label's float normalisation, %llu off by more than 1/16 px (%llu views), %llu "
      "pixels shared by two points\n",
      static_cast<unsigned long long>(inexact_points),
      static_cast<unsigned long long>(far_points),
      static_cast<unsigned long long>(far_views),
      static_cast<unsigned long long>(merged));
  std::printf(
      "  decode: %llu views differ from their pixels after the round trip; %llu points "
      "decoded per pass\n",
      static_cast<unsigned long long>(mismatched),
      static_cast<unsigned long long>(sink / static_cast<uint64_t>(reps)));
  std::printf("  PointQ: %.1f bytes/view (32 bits/point)\n", pointq_per_view);
  std::printf(
      "  coded:  %.1f bytes/view (median %zu, p95 %zu, max %zu), %.2f bits/point; "
      "ratio %.3f\n",
      coded_per_view,
      sizes[sizes.size() / 2],
      sizes[sizes.size() * 95 / 100],
      sizes.back(),
      8.0 * coded / points,
      coded / (4.0 * points));
  std::printf(
      "    per view: %.1f chains, starts %.1f bits/chain, moves %.2f bits/point, header "
      "%.1f bytes\n",
      static_cast<double>(stats.chains) / n,
      static_cast<double>(stats.start_bits) / stats.chains,
      static_cast<double>(stats.move_bits) / stats.pixels,
      static_cast<double>(stats.header_bytes) / n);
  std::printf(
      "  view codes (EncodeViewPoints: exactly the stored points): %llu lattice-mode views, %llu "
      "raw; %.1f bytes/view (%.2f bits/point); %llu views differ after the round trip; decode "
      "to PointQ %.2f us/view\n",
      static_cast<unsigned long long>(view_lattice),
      static_cast<unsigned long long>(view_raw),
      view_per_view,
      8.0 * static_cast<double>(view_bytes) / static_cast<double>(points),
      static_cast<unsigned long long>(view_mismatched),
      view_decode_us[view_decode_us.size() / 2]);
  std::printf(
      "  encode %.2f us/view; decode %.2f us/view, + to PointQ %.2f us/view "
      "(medians of %d passes, 1 thread)\n",
      1e6 * encode_seconds / n,
      decode_us[decode_us.size() / 2],
      normalise_us[normalise_us.size() / 2],
      reps);
  for (int c = 0; c < 2; ++c) {
    const std::vector<int> lengths = HuffmanLengths(stats.symbols[c], 9);
    std::printf("  context %d (%s): counts", c, c == 0 ? "after axial/start" : "after diagonal");
    for (int s = 0; s < 9; ++s) {
      std::printf(" %llu", static_cast<unsigned long long>(stats.symbols[c][s]));
    }
    std::printf("; Huffman lengths {");
    for (int s = 0; s < 9; ++s) std::printf("%d%s", lengths[s], s < 8 ? ", " : "}\n");
  }
  // The coarse fields (1,849 bytes per view raw): coded (format/field_codec.h), checked, timed.
  uint64_t field_views = 0, field_bytes = 0, field_mismatched = 0;
  std::vector<double> field_decode_us;
  {
    std::vector<std::string> field_codes;
    std::array<uint8_t, CoarseGrid::kCells> back_field{};
    for (size_t v = 0; v < n; ++v) {
      const uint8_t* f = db.coarse_field(static_cast<view_id_t>(v));
      if (f == nullptr) continue;
      field_codes.emplace_back();
      EncodeCoarseField(std::span<const uint8_t, CoarseGrid::kCells>(f, CoarseGrid::kCells),
                        &field_codes.back());
      field_bytes += field_codes.back().size();
      const Status st = DecodeCoarseField(Bytes(field_codes.back()), back_field);
      field_mismatched += !st.ok() || !std::equal(back_field.begin(), back_field.end(), f);
      ++field_views;
    }
    for (int r = 0; r < reps && !field_codes.empty(); ++r) {
      const double t0 = Now();
      for (const std::string& c : field_codes) (void)DecodeCoarseField(Bytes(c), back_field);
      field_decode_us.push_back(1e6 * (Now() - t0) / static_cast<double>(field_codes.size()));
    }
    std::sort(field_decode_us.begin(), field_decode_us.end());
  }
  const double field_raw = CoarseGrid::kCells;
  const double field_coded =
      field_views > 0 ? static_cast<double>(field_bytes) / static_cast<double>(field_views)
                      : field_raw;
  if (field_views > 0) {
    std::printf(
        "  coarse fields (%llu views): %.0f bytes raw, coded %.1f bytes/view (%.2f "
        "bits/cell), %llu differ after the round trip; decode %.2f us/view\n",
        static_cast<unsigned long long>(field_views),
        field_raw,
        field_coded,
        8 * field_coded / field_raw,
        static_cast<unsigned long long>(field_mismatched),
        field_decode_us[field_decode_us.size() / 2]);
  }
  std::printf(
      "  storage per canonical view: shards %.0f (points %.0f as PointQ) + index %.0f = "
      "%.0f bytes; %.1f per virtual view\n",
      shards_per_view,
      pointq_per_view,
      index_per_view,
      shards_per_view + index_per_view,
      (shards_per_view + index_per_view) / rolls);
  std::printf(
      "  with coded points (view codes): shards %.0f + index %.0f = %.0f bytes; %.1f per virtual "
      "view\n",
      with_code,
      index_per_view,
      with_code + index_per_view,
      (with_code + index_per_view) / rolls);
  if (field_views > 0) {
    const double both = with_code - field_raw + field_coded;
    std::printf(
        "  with coded points and fields: shards %.0f + index %.0f = %.0f bytes; "
        "%.1f per virtual view (target 40 at R = 48)\n",
        both,
        index_per_view,
        both + index_per_view,
        (both + index_per_view) / rolls);
  }
  return 0;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) { return handdb::Run(argc, argv); }
