#include "nn/tflite_ops.h"

// One thread per Run (EIGEN_DONT_PARALLELIZE, set for this whole library in nn/CMakeLists.txt):
// callers run photos in parallel, and Eigen's own threads would spin against them.
#include <Eigen/Core>
#include <cmath>
#include <cstring>
#include <limits>

namespace handdb::tflite {
namespace {

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

}  // namespace

void Conv2d(const float* x,
            std::span<const int> x_shape,
            const float* weights,
            const float* bias,
            const Window& win,
            std::span<const int> y_shape,
            float* y,
            std::vector<float>* patches) {
  const int h = x_shape[1], w = x_shape[2], c = x_shape[3];
  const int oh = y_shape[1], ow = y_shape[2], o = y_shape[3];
  const int cols = win.kh * win.kw * c;
  Eigen::Map<const RowMatrix> kernel(weights, o, cols);
  Eigen::Map<RowMatrix> out(y, static_cast<Eigen::Index>(oh) * ow, o);
  if (win.kh == 1 && win.kw == 1 && win.stride_h == 1 && win.stride_w == 1) {
    Eigen::Map<const RowMatrix> in(x, static_cast<Eigen::Index>(h) * w, c);
    out.noalias() = in * kernel.transpose();
  } else {
    const int pt = win.pad_before(h, win.kh, win.stride_h);
    const int pl = win.pad_before(w, win.kw, win.stride_w);
    patches->assign(static_cast<size_t>(oh) * ow * cols, 0.0f);  // padding stays 0
    for (int r = 0; r < oh; ++r) {
      for (int s = 0; s < ow; ++s) {
        float* dst = patches->data() + (static_cast<size_t>(r) * ow + s) * cols;
        for (int i = 0; i < win.kh; ++i) {
          const int yy = r * win.stride_h + i - pt;
          if (yy < 0 || yy >= h) continue;
          for (int j = 0; j < win.kw; ++j) {
            const int xx = s * win.stride_w + j - pl;
            if (xx < 0 || xx >= w) continue;
            std::memcpy(dst + (i * win.kw + j) * c,
                        x + (static_cast<size_t>(yy) * w + xx) * c,
                        sizeof(float) * c);
          }
        }
      }
    }
    Eigen::Map<const RowMatrix> in(patches->data(), static_cast<Eigen::Index>(oh) * ow, cols);
    out.noalias() = in * kernel.transpose();
  }
  if (bias != nullptr) out.rowwise() += Eigen::Map<const Eigen::RowVectorXf>(bias, o);
}

void DepthwiseConv2d(const float* x,
                     std::span<const int> x_shape,
                     const float* weights,
                     const float* bias,
                     const Window& win,
                     std::span<const int> y_shape,
                     float* y) {
  const int h = x_shape[1], w = x_shape[2], c = x_shape[3];
  const int oh = y_shape[1], ow = y_shape[2];
  const int pt = win.pad_before(h, win.kh, win.stride_h);
  const int pl = win.pad_before(w, win.kw, win.stride_w);
  for (int r = 0; r < oh; ++r) {
    for (int s = 0; s < ow; ++s) {
      float* dst = y + (static_cast<size_t>(r) * ow + s) * c;
      if (bias != nullptr) {
        std::memcpy(dst, bias, sizeof(float) * c);
      } else {
        std::fill(dst, dst + c, 0.0f);
      }
      for (int i = 0; i < win.kh; ++i) {
        const int yy = r * win.stride_h + i - pt;
        if (yy < 0 || yy >= h) continue;
        for (int j = 0; j < win.kw; ++j) {
          const int xx = s * win.stride_w + j - pl;
          if (xx < 0 || xx >= w) continue;
          const float* src = x + (static_cast<size_t>(yy) * w + xx) * c;
          const float* kern = weights + static_cast<size_t>(i * win.kw + j) * c;
          for (int ch = 0; ch < c; ++ch) dst[ch] += src[ch] * kern[ch];
        }
      }
    }
  }
}

void MaxPool2d(const float* x,
               std::span<const int> x_shape,
               const Window& win,
               std::span<const int> y_shape,
               float* y) {
  const int h = x_shape[1], w = x_shape[2], c = x_shape[3];
  const int oh = y_shape[1], ow = y_shape[2];
  const int pt = win.pad_before(h, win.kh, win.stride_h);
  const int pl = win.pad_before(w, win.kw, win.stride_w);
  for (int r = 0; r < oh; ++r) {
    for (int s = 0; s < ow; ++s) {
      float* dst = y + (static_cast<size_t>(r) * ow + s) * c;
      std::fill(dst, dst + c, -std::numeric_limits<float>::infinity());
      for (int i = 0; i < win.kh; ++i) {
        const int yy = r * win.stride_h + i - pt;
        if (yy < 0 || yy >= h) continue;
        for (int j = 0; j < win.kw; ++j) {
          const int xx = s * win.stride_w + j - pl;
          if (xx < 0 || xx >= w) continue;
          const float* src = x + (static_cast<size_t>(yy) * w + xx) * c;
          for (int ch = 0; ch < c; ++ch) dst[ch] = std::max(dst[ch], src[ch]);
        }
      }
    }
  }
}

void Add(const float* x, const float* z, int64_t n, float* y) {
  for (int64_t i = 0; i < n; ++i) y[i] = x[i] + z[i];
}

void FullyConnected(const float* x,
                    int64_t batch,
                    const float* weights,
                    int out,
                    int in,
                    const float* bias,
                    float* y) {
  Eigen::Map<const RowMatrix> kernel(weights, out, in);
  Eigen::Map<const RowMatrix> xs(x, batch, in);
  Eigen::Map<RowMatrix> ys(y, batch, out);
  ys.noalias() = xs * kernel.transpose();
  if (bias != nullptr) ys.rowwise() += Eigen::Map<const Eigen::RowVectorXf>(bias, out);
}

void Logistic(const float* x, int64_t n, float* y) {
  for (int64_t i = 0; i < n; ++i) y[i] = 1.0f / (1.0f + std::exp(-x[i]));
}

void MeanHW(const float* x, std::span<const int> x_shape, float* y) {
  const int64_t hw = static_cast<int64_t>(x_shape[1]) * x_shape[2];
  const int c = x_shape[3];
  std::fill(y, y + c, 0.0f);
  for (int64_t i = 0; i < hw; ++i) {
    for (int ch = 0; ch < c; ++ch) y[ch] += x[i * c + ch];
  }
  for (int ch = 0; ch < c; ++ch) y[ch] /= static_cast<float>(hw);
}

void Activate(int activation, float* v, size_t n) {
  switch (activation) {
    case 1:
      for (size_t i = 0; i < n; ++i) v[i] = std::max(v[i], 0.0f);
      break;
    case 2:
      for (size_t i = 0; i < n; ++i) v[i] = std::clamp(v[i], -1.0f, 1.0f);
      break;
    case 3:
      for (size_t i = 0; i < n; ++i) v[i] = std::clamp(v[i], 0.0f, 6.0f);
      break;
    case 4:
      for (size_t i = 0; i < n; ++i) v[i] = std::tanh(v[i]);
      break;
    default:
      break;
  }
}

}  // namespace handdb::tflite
