#include "format/field_codec.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <vector>

namespace handdb {
namespace {

using Field = std::array<uint8_t, CoarseGrid::kCells>;

std::span<const uint8_t> Bytes(const std::string& s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

// The field of a hand-like outline: two ellipses and a line, in PointQ units.
Field CurveField(double shift_px) {
  std::vector<PointQ> points;
  for (int e = 0; e < 2; ++e) {
    for (int i = 0; i < 600; ++i) {
      const double t = 2 * M_PI * i / 600;
      points.push_back({static_cast<int16_t>(16 * (shift_px + (60 + 20 * e) * std::cos(t))),
                        static_cast<int16_t>(16 * ((90 - 30 * e) * std::sin(t)))});
    }
  }
  for (int i = -80; i < 80; ++i) points.push_back({static_cast<int16_t>(16 * i), 16 * 20});
  Field f{};
  ComputeCoarseField(points, f.data());
  return f;
}

void ExpectRoundTrip(const Field& f) {
  std::string code;
  EncodeCoarseField(f, &code);
  Field back{};
  const Status s = DecodeCoarseField(Bytes(code), back);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(back, f);
}

TEST(FieldCodec, RoundTripsFieldsOfAnyContent) {
  ExpectRoundTrip(CurveField(0));
  ExpectRoundTrip(CurveField(-37.5));
  Field zeros{};  // an empty view's field
  ExpectRoundTrip(zeros);
  Field full;
  full.fill(255);
  ExpectRoundTrip(full);
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {  // noise: nearly every cell escaped
    Field noise;
    for (uint8_t& b : noise) b = static_cast<uint8_t>(rng());
    ExpectRoundTrip(noise);
  }
}

TEST(FieldCodec, AnOutlinesFieldTakesUnderHalfItsBytes) {
  std::string code;
  EncodeCoarseField(CurveField(0), &code);
  EXPECT_LT(code.size(), CoarseGrid::kCells / 2) << code.size();
}

TEST(FieldCodec, DamagedCodesAreErrorsNeverCrashes) {
  std::string code;
  EncodeCoarseField(CurveField(5), &code);
  Field back{};
  for (size_t len = 0; len < code.size(); ++len) {
    EXPECT_FALSE(DecodeCoarseField(Bytes(code).first(len), back).ok()) << "length " << len;
  }
  EXPECT_EQ(DecodeCoarseField(Bytes(code + std::string(1, '\0')), back).code(),
            StatusCode::kSizeMismatch);
  int failed = 0;
  for (size_t bit = 0; bit < 8 * code.size(); ++bit) {
    std::string flipped = code;
    flipped[bit / 8] = static_cast<char>(flipped[bit / 8] ^ (1 << (bit % 8)));
    const Status s = DecodeCoarseField(Bytes(flipped), back);
    if (!s.ok()) {
      ++failed;
      EXPECT_FALSE(s.message().empty());
    }
  }
  EXPECT_GT(failed, 0);
}

}  // namespace
}  // namespace handdb
