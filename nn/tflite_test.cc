// Each operator of the TFLite interpreter against a direct computation: three small models
// (tests/data/tflite, written by make_models.py there with weights from a fixed formula) run on
// a fixed input, and the same arithmetic done here with plain loops and TFLite's SAME/VALID
// padding rule. Each on both backends: the portable kernels and XNNPACK (when built in).
#include "nn/tflite.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace handdb {
namespace {

namespace fs = std::filesystem;

fs::path ModelPath(const char* name) {
  const char* env = std::getenv("HANDDB_SOURCE_DIR");
  return (env != nullptr ? fs::path(env) : fs::path(".")) / "tests" / "data" / "tflite" / name;
}

// make_models.py's weights: ((i * 7 + seed) % 11 - 5) / 8.
std::vector<float> Weights(int n, int seed) {
  std::vector<float> w(n);
  for (int i = 0; i < n; ++i) w[i] = static_cast<float>((i * 7 + seed) % 11 - 5) / 8.0f;
  return w;
}

std::vector<float> Input(int n) {
  std::vector<float> x(n);
  for (int i = 0; i < n; ++i) x[i] = static_cast<float>((i * 5) % 13 - 6) / 4.0f;
  return x;
}

struct Shape {
  int h, w, c;
  int at(int y, int x, int ch) const { return (y * w + x) * c + ch; }
};

// TFLite's padding: SAME -> out = ceil(in / stride), the total padding split with the smaller
// half before; VALID -> out = (in - k) / stride + 1, no padding.
int OutSize(int in, int k, int stride, bool same) {
  return same ? (in + stride - 1) / stride : (in - k) / stride + 1;
}
int PadBefore(int in, int k, int stride, bool same) {
  if (!same) return 0;
  return std::max((OutSize(in, k, stride, true) - 1) * stride + k - in, 0) / 2;
}

// Convolution (depthwise: each channel with its own kernel), weights [O][kh][kw][C] or
// [1][kh][kw][C].
std::vector<float> Conv(const std::vector<float>& x,
                        Shape s,
                        const std::vector<float>& w,
                        const std::vector<float>& bias,
                        int out_c,
                        int k,
                        int stride,
                        bool depthwise,
                        Shape* out_shape) {
  const int oh = OutSize(s.h, k, stride, true), ow = OutSize(s.w, k, stride, true);
  const int pt = PadBefore(s.h, k, stride, true), pl = PadBefore(s.w, k, stride, true);
  Shape o{oh, ow, out_c};
  std::vector<float> y(oh * ow * out_c);
  for (int r = 0; r < oh; ++r) {
    for (int q = 0; q < ow; ++q) {
      for (int f = 0; f < out_c; ++f) {
        double sum = bias.empty() ? 0.0 : bias[f];
        for (int i = 0; i < k; ++i) {
          for (int j = 0; j < k; ++j) {
            const int yy = r * stride + i - pt, xx = q * stride + j - pl;
            if (yy < 0 || yy >= s.h || xx < 0 || xx >= s.w) continue;
            if (depthwise) {
              sum += x[s.at(yy, xx, f)] * w[(i * k + j) * s.c + f];
            } else {
              for (int ch = 0; ch < s.c; ++ch) {
                sum += x[s.at(yy, xx, ch)] * w[((f * k + i) * k + j) * s.c + ch];
              }
            }
          }
        }
        y[o.at(r, q, f)] = static_cast<float>(sum);
      }
    }
  }
  *out_shape = o;
  return y;
}

// Loads a model on the backend under test. XNNPACK runs every operator of these models: when it
// is built in, a fallback to the portable kernels is a failure.
class TfliteOperatorsTest : public ::testing::TestWithParam<TfliteBackend> {
 protected:
  Result<TfliteModel> Load(const char* name) {
    auto m = TfliteModel::Load(ModelPath(name), GetParam());
    if (m.ok()) {
#if HANDDB_HAVE_XNNPACK
      EXPECT_EQ(m->backend(), GetParam());
#else
      EXPECT_EQ(m->backend(), TfliteBackend::kPortable);
#endif
    }
    return m;
  }
};

INSTANTIATE_TEST_SUITE_P(Backends,
                         TfliteOperatorsTest,
                         ::testing::Values(TfliteBackend::kPortable, TfliteBackend::kXnnpack),
                         [](const ::testing::TestParamInfo<TfliteBackend>& info) {
                           return info.param == TfliteBackend::kPortable ? "Portable" : "Xnnpack";
                         });

void ExpectNear(const std::vector<float>& got, const std::vector<float>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < got.size(); ++i) {
    EXPECT_NEAR(got[i], want[i], 1e-5 * std::max(1.0f, std::abs(want[i]))) << "element " << i;
  }
}

TEST_P(TfliteOperatorsTest, ConvolutionsWithSamePaddingStridesBiasRelu6AndFloat16Weights) {
  auto m = Load("conv.tflite");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  const Shape s{5, 6, 3};
  const std::vector<float> x = Input(5 * 6 * 3);
  Shape s1, s2;
  std::vector<float> t = Conv(x, s, Weights(108, 1), Weights(4, 2), 4, 3, 2, false, &s1);
  for (float& v : t) v = std::clamp(v, 0.0f, 6.0f);
  ASSERT_EQ(s1.h, 3);
  ASSERT_EQ(s1.w, 3);
  const std::vector<float> want = Conv(t, s1, Weights(8, 3), Weights(2, 4), 2, 1, 1, false, &s2);
  const auto out = m->Run(x);
  ASSERT_EQ(out.size(), 1u);
  ExpectNear(out[0], want);
}

TEST_P(TfliteOperatorsTest, DepthwiseAddAndLogistic) {
  auto m = Load("depthwise.tflite");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  const Shape s{5, 5, 3};
  const std::vector<float> x = Input(5 * 5 * 3);
  Shape s1, s2;
  const std::vector<float> a = Conv(x, s, Weights(27, 5), Weights(3, 6), 3, 3, 2, true, &s1);
  const std::vector<float> b = Conv(a, s1, Weights(27, 7), {}, 3, 3, 1, true, &s2);
  std::vector<float> want(a.size());
  for (size_t i = 0; i < a.size(); ++i) want[i] = 1.0f / (1.0f + std::exp(-(a[i] + b[i])));
  // Twice through one workspace: the buffers it keeps must not leak one run into the next.
  auto ws = m->NewWorkspace();
  ExpectNear(m->Run(x, ws.get())[0], want);
  ExpectNear(m->Run(x, ws.get())[0], want);
}

TEST_P(TfliteOperatorsTest, MaxPoolMeanAndFullyConnected) {
  auto m = Load("head.tflite");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  const Shape s{4, 4, 3};
  const std::vector<float> x = Input(4 * 4 * 3);
  std::vector<double> mean(3, 0.0);
  for (int r = 0; r < 2; ++r) {
    for (int q = 0; q < 2; ++q) {
      for (int ch = 0; ch < 3; ++ch) {
        float v = -INFINITY;
        for (int i = 0; i < 2; ++i) {
          for (int j = 0; j < 2; ++j) v = std::max(v, x[s.at(2 * r + i, 2 * q + j, ch)]);
        }
        mean[ch] += v / 4.0;
      }
    }
  }
  const std::vector<float> w = Weights(6, 8), b = Weights(2, 9);
  std::vector<float> want(2);
  for (int o = 0; o < 2; ++o) {
    double sum = b[o];
    for (int k = 0; k < 3; ++k) sum += mean[k] * w[o * 3 + k];
    want[o] = static_cast<float>(sum);
  }
  EXPECT_EQ(m->input_shape(), (std::vector<int>{1, 4, 4, 3}));
  EXPECT_EQ(m->output_sizes(), (std::vector<size_t>{2}));
  ExpectNear(m->Run(x)[0], want);
}

// Inputs the fuzzer found (tests/fuzz/tflite_fuzzer.cc): each was read out of bounds before the
// check that now refuses it.
TEST_P(TfliteOperatorsTest, RefusesWhatItCannotRunSafely) {
  auto int32_weights = Load("bad_int32_weights.tflite");
  ASSERT_FALSE(int32_weights.ok());
  EXPECT_EQ(int32_weights.status().code(), StatusCode::kSizeMismatch);
  EXPECT_NE(int32_weights.status().message().find("FULLY_CONNECTED"), std::string::npos)
      << int32_weights.status().ToString();
  auto no_output = Load("bad_no_output.tflite");
  ASSERT_FALSE(no_output.ok());
  EXPECT_EQ(no_output.status().code(), StatusCode::kBadLayout);
  EXPECT_NE(no_output.status().message().find(
                "bad_no_output.tflite: operator 0 has 1 inputs and 0 outputs"),
            std::string::npos)
      << no_output.status().ToString();
}

}  // namespace
}  // namespace handdb
