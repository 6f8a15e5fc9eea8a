#include "format/point_codec.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>

namespace handdb {
namespace {

std::vector<LatticePixel> Raster(std::vector<LatticePixel> p) {
  std::sort(p.begin(), p.end(), [](const LatticePixel& a, const LatticePixel& b) {
    return a.row != b.row ? a.row < b.row : a.col < b.col;
  });
  p.erase(std::unique(p.begin(), p.end()), p.end());
  return p;
}

std::string Encode(const std::vector<LatticePixel>& p) {
  std::string code;
  const Status s = EncodeLatticePixels(p, &code);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return code;
}

std::span<const uint8_t> Bytes(const std::string& s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

void ExpectRoundTrip(const std::vector<LatticePixel>& p) {
  const std::string code = Encode(p);
  std::vector<LatticePixel> back;
  const Status s = DecodeLatticePixels(Bytes(code), &back);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(back, Raster(p));
}

// Outlines of a few overlapping ellipses and a line across them: thin curves like a view's edges,
// with junctions, 4- and 8-connected steps.
std::vector<LatticePixel> Curves(int ox, int oy) {
  std::vector<LatticePixel> p;
  for (int e = 0; e < 4; ++e) {
    const double a = 30 + 12 * e, b = 18 + 9 * e, cx = 100 + 15 * e, cy = 80 + 5 * e;
    for (int i = 0; i < 2000; ++i) {
      const double t = 2 * M_PI * i / 2000;
      p.push_back({ox + static_cast<int>(std::floor(cx + a * std::cos(t))),
                   oy + static_cast<int>(std::floor(cy + b * std::sin(t)))});
    }
  }
  for (int x = 40; x < 200; ++x) p.push_back({ox + x, oy + 60 + x / 3});
  return p;
}

TEST(PointCodec, RoundTripsCurvesInRasterOrder) {
  const std::vector<LatticePixel> p = Curves(0, 0);
  ExpectRoundTrip(p);
  // About 2 bits per pixel on curves (the point of the codec): far below PointQ's 32.
  const std::string code = Encode(p);
  EXPECT_LT(8.0 * code.size() / Raster(p).size(), 4.0);
  // Any order and duplicates give the same code.
  std::vector<LatticePixel> shuffled = p;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(7));
  shuffled.insert(shuffled.end(), p.begin(), p.begin() + 50);
  EXPECT_EQ(Encode(shuffled), code);
  // Negative and large coordinates.
  ExpectRoundTrip(Curves(-5000, -70000));
  ExpectRoundTrip(Curves(2000000000, 100));
}

TEST(PointCodec, SmallAndScatteredSets) {
  ExpectRoundTrip({});
  EXPECT_EQ(Encode({}), std::string(1, '\0'));
  ExpectRoundTrip({{3, 4}});
  ExpectRoundTrip({{3, 4}, {4, 4}});
  ExpectRoundTrip({{3, 4}, {2, 5}});  // the first move goes south-west
  ExpectRoundTrip({{0, 0}, {kMaxLatticeSide - 1, kMaxLatticeSide - 1}});
  std::mt19937 rng(11);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<LatticePixel> p;
    std::uniform_int_distribution<int> coord(-40, 40);
    const int n = 1 + trial * 13;
    for (int i = 0; i < n; ++i) p.push_back({coord(rng), coord(rng)});
    ExpectRoundTrip(p);
  }
  // A full block: every pixel a neighbour of many.
  std::vector<LatticePixel> block;
  for (int y = 0; y < 20; ++y) {
    for (int x = 0; x < 30; ++x) block.push_back({x, y});
  }
  ExpectRoundTrip(block);
}

TEST(PointCodec, RefusesABoxTooLargeToCode) {
  std::string code;
  const Status s =
      EncodeLatticePixels(std::vector<LatticePixel>{{0, 0}, {kMaxLatticeSide, 0}}, &code);
  EXPECT_EQ(s.code(), StatusCode::kOutOfRange);
  EXPECT_NE(s.message().find("8192"), std::string::npos) << s.message();
}

TEST(PointCodec, DamagedCodesAreErrorsNeverCrashes) {
  const std::vector<LatticePixel> p = Curves(10, 20);
  const std::string code = Encode(p);
  std::vector<LatticePixel> back;
  // Every truncation is an error.
  for (size_t len = 0; len < code.size(); ++len) {
    const Status s = DecodeLatticePixels(Bytes(code).first(len), &back);
    EXPECT_FALSE(s.ok()) << "length " << len;
  }
  // A byte more is an error.
  EXPECT_FALSE(DecodeLatticePixels(Bytes(code + std::string(1, '\0')), &back).ok());
  // Every single-bit flip either fails with a message or decodes to some valid set; never a
  // crash or a read outside the code (the sanitizer stage runs this test).
  int failed = 0;
  for (size_t bit = 0; bit < 8 * code.size(); ++bit) {
    std::string flipped = code;
    flipped[bit / 8] = static_cast<char>(flipped[bit / 8] ^ (1 << (bit % 8)));
    const Status s = DecodeLatticePixels(Bytes(flipped), &back);
    if (!s.ok()) {
      ++failed;
      EXPECT_FALSE(s.message().empty());
    }
  }
  EXPECT_GT(failed, 0);
  // Hostile headers: a count that cannot fit the box, a box wider than allowed.
  std::string huge_count;
  huge_count.push_back('\xff');
  huge_count.push_back('\x7f');                      // n = 16383
  huge_count += std::string("\x00\x00\x01\x01", 4);  // a 2 x 2 box at (0, 0)
  EXPECT_EQ(DecodeLatticePixels(Bytes(huge_count), &back).code(), StatusCode::kSizeMismatch);
  std::string wide = std::string("\x01\x00\x00", 3);
  wide += std::string("\x80\x40\x00", 3);  // width - 1 = 8192
  EXPECT_EQ(DecodeLatticePixels(Bytes(wide), &back).code(), StatusCode::kOutOfRange);
}

TEST(PointCodec, StatsCountWhatWasCoded) {
  const std::vector<LatticePixel> p = Curves(0, 0);
  std::string code;
  LatticeCodeStats stats;
  ASSERT_TRUE(EncodeLatticePixels(p, &code, &stats).ok());
  EXPECT_EQ(stats.pixels, Raster(p).size());
  uint64_t symbols = 0, ends = 0;
  for (const auto& context : stats.symbols) {
    for (int s = 0; s < 9; ++s) symbols += context[s];
    ends += context[8];
  }
  EXPECT_EQ(ends, stats.chains);
  EXPECT_EQ(symbols, stats.pixels);  // one move per pixel but each chain's first, one end each
  EXPECT_EQ(stats.header_bytes + (stats.start_bits + stats.move_bits + 7) / 8, code.size());
}

// Points as the converter makes them: pixels normalised in double (edges/normalise.cc), sorted.
std::vector<PointQ> Normalised(const std::vector<LatticePixel>& pixels,
                               double scale,
                               double cx,
                               double cy) {
  std::vector<PointQ> out;
  for (const LatticePixel& p : Raster(pixels)) {
    out.push_back({static_cast<int16_t>(std::nearbyint((p.col + 0.5 - cx) * scale * 16)),
                   static_cast<int16_t>(std::nearbyint((p.row + 0.5 - cy) * scale * 16))});
  }
  std::sort(out.begin(), out.end(), [](const PointQ& a, const PointQ& b) {
    return a.y != b.y ? a.y < b.y : a.x < b.x;
  });
  return out;
}

void ExpectViewRoundTrip(const std::vector<PointQ>& points,
                         float scale,
                         std::array<float, 2> centre,
                         int want_mode,
                         size_t* bytes = nullptr) {
  std::string code;
  int mode = -1;
  const Status s = EncodeViewPoints(points, scale, centre, &code, &mode);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(mode, want_mode);
  std::vector<PointQ> back;
  const Status d = DecodeViewPoints(Bytes(code), scale, centre, &back);
  ASSERT_TRUE(d.ok()) << d.ToString();
  ASSERT_EQ(back.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    ASSERT_TRUE(back[i].x == points[i].x && back[i].y == points[i].y) << i;
  }
  if (bytes) *bytes = code.size();
}

TEST(PointCodec, ViewPointsComeBackExactly) {
  // Converted views: on the lattice, normalised in double, the record's float values decode them
  // (with corrections where float and double round differently).
  const std::vector<LatticePixel> pixels = Curves(20, 30);
  for (const double scale : {0.7312345678, 1.0, 1.2345678901}) {
    const double cx = 127.123456789, cy = 131.987654321;
    const std::vector<PointQ> points = Normalised(pixels, scale, cx, cy);
    size_t bytes = 0;
    ExpectViewRoundTrip(points,
                        static_cast<float>(scale),
                        {static_cast<float>(cx), static_cast<float>(cy)},
                        0,
                        &bytes);
    EXPECT_LT(bytes, points.size());  // under a byte per point, against PointQ's four
  }
  // Points off any lattice, an unusable scale, nothing: mode 1, still exact.
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> coord(-3000, 3000);
  std::vector<PointQ> scattered;
  for (int i = 0; i < 400; ++i) {
    scattered.push_back({static_cast<int16_t>(coord(rng)), static_cast<int16_t>(coord(rng))});
  }
  std::sort(scattered.begin(), scattered.end(), [](const PointQ& a, const PointQ& b) {
    return a.y != b.y ? a.y < b.y : a.x < b.x;
  });
  scattered.erase(
      std::unique(scattered.begin(),
                  scattered.end(),
                  [](const PointQ& a, const PointQ& b) { return a.x == b.x && a.y == b.y; }),
      scattered.end());
  ExpectViewRoundTrip(scattered, 1.0f, {128.0f, 128.0f}, 1);
  const std::vector<PointQ> lattice_points = Normalised(pixels, 1.0, 128, 128);
  ExpectViewRoundTrip(lattice_points, 0.0f, {128.0f, 128.0f}, 1);
  ExpectViewRoundTrip(lattice_points, std::nanf(""), {128.0f, 128.0f}, 1);
  ExpectViewRoundTrip({}, 1.0f, {0.0f, 0.0f}, 1);
  ExpectViewRoundTrip({{-32768, -32768}, {32767, 32767}}, 1.0f, {0.0f, 0.0f}, 1);
  // Any order, repeats included (bench/synth_db's views are not sorted): mode 1.
  std::vector<PointQ> unsorted(lattice_points.rbegin(), lattice_points.rend());
  unsorted.push_back(unsorted.front());
  ExpectViewRoundTrip(unsorted, 1.0f, {128.0f, 128.0f}, 1);
}

TEST(PointCodec, PeekGivesTheCountAndABoundWithoutDecoding) {
  const std::vector<LatticePixel> pixels = Curves(20, 30);
  for (const double scale : {0.7312345678, 1.2345678901}) {
    const float fs = static_cast<float>(scale);
    const std::array<float, 2> centre = {127.123456789f, 131.987654321f};
    const std::vector<PointQ> points = Normalised(pixels, scale, centre[0], centre[1]);
    std::string code;
    int mode = -1;
    ASSERT_TRUE(EncodeViewPoints(points, fs, centre, &code, &mode).ok());
    ASSERT_EQ(mode, 0);
    ViewPointsExtent e;
    ASSERT_TRUE(PeekViewPoints(Bytes(code), fs, centre, &e).ok());
    EXPECT_TRUE(e.peeked && e.sorted);
    EXPECT_EQ(e.count, points.size());
    int32_t max_abs = 0;
    for (const PointQ& p : points) {
      max_abs = std::max(
          {max_abs, std::abs(static_cast<int32_t>(p.x)), std::abs(static_cast<int32_t>(p.y))});
    }
    EXPECT_GE(e.max_abs_bound, max_abs);
    EXPECT_LE(e.max_abs_bound, max_abs + 2 * static_cast<int32_t>(scale * 16) + 2);
    // Every truncation of the header is an error; past it, the peek does not look.
    for (size_t len = 0; len < 4; ++len) {
      EXPECT_FALSE(PeekViewPoints(Bytes(code).first(len), fs, centre, &e).ok()) << len;
    }
  }
  // A raw-mode code: only decoding tells.
  std::string raw;
  ASSERT_TRUE(EncodeViewPoints(std::vector<PointQ>{{5, 1}, {-3, 0}}, 1.0f, {0, 0}, &raw).ok());
  ViewPointsExtent e;
  ASSERT_TRUE(PeekViewPoints(Bytes(raw), 1.0f, {0, 0}, &e).ok());
  EXPECT_FALSE(e.peeked);
}

TEST(PointCodec, CorrectionsOfMoreThanASixteenthArePlainCode) {
  // A point 2/16 px off its pixel's point: the lattice code would need a correction of 2, which
  // the decoder refuses (it would break PeekViewPoints' bound), so the view takes mode 1.
  std::vector<PointQ> points = Normalised(Curves(0, 0), 1.1, 120.3, 119.7);
  ExpectViewRoundTrip(points, 1.1f, {120.3f, 119.7f}, 0);
  points[points.size() / 2].x = static_cast<int16_t>(points[points.size() / 2].x + 2);
  std::sort(points.begin(), points.end(), [](const PointQ& a, const PointQ& b) {
    return a.y != b.y ? a.y < b.y : a.x < b.x;
  });
  ExpectViewRoundTrip(points, 1.1f, {120.3f, 119.7f}, 1);
}

TEST(PointCodec, DamagedViewCodesAreErrorsNeverCrashes) {
  const std::vector<PointQ> points = Normalised(Curves(0, 0), 1.1, 120.3, 119.7);
  for (const float scale : {1.1f, 0.0f}) {  // mode 0, mode 1
    std::string code;
    ASSERT_TRUE(EncodeViewPoints(points, scale, {120.3f, 119.7f}, &code).ok());
    std::vector<PointQ> back;
    for (size_t len = 0; len < code.size(); ++len) {
      EXPECT_FALSE(DecodeViewPoints(Bytes(code).first(len), scale, {120.3f, 119.7f}, &back).ok())
          << "length " << len;
    }
    for (size_t bit = 0; bit < 8 * code.size(); bit += 3) {
      std::string flipped = code;
      flipped[bit / 8] = static_cast<char>(flipped[bit / 8] ^ (1 << (bit % 8)));
      const Status s = DecodeViewPoints(Bytes(flipped), scale, {120.3f, 119.7f}, &back);
      if (s.ok() && flipped[0] == 0) {  // a lattice-mode decode is sorted and unique
        for (size_t i = 1; i < back.size(); ++i) {
          ASSERT_TRUE(back[i - 1].y < back[i].y ||
                      (back[i - 1].y == back[i].y && back[i - 1].x < back[i].x));
        }
      }
    }
  }
}

}  // namespace
}  // namespace handdb
