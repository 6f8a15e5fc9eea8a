// The operators of the TFLite runtime (nn/tflite.h): float32 kernels over NHWC tensors with N = 1.
// They index blindly: TfliteModel::Load has checked every shape an operator is run with, so
// only nn/tflite.cc calls them.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace handdb::tflite {

enum class Padding { kSame, kValid };

// A convolution's or pool's kernel, strides and padding (TFLite's SAME and VALID).
struct Window {
  Padding padding = Padding::kSame;
  int stride_w = 1, stride_h = 1;
  int kw = 1, kh = 1;
  int out(int in, int k, int stride) const {
    return padding == Padding::kSame ? (in + stride - 1) / stride : (in - k + stride) / stride;
  }
  int pad_before(int in, int k, int stride) const {
    if (padding == Padding::kValid) return 0;
    const int o = out(in, k, stride);
    return std::max((o - 1) * stride + k - in, 0) / 2;
  }
};

// CONV_2D: weights O x KH x KW x C, bias O or null. `patches` holds the im2col rows between calls.
void Conv2d(const float* x,
            std::span<const int> x_shape,
            const float* weights,
            const float* bias,
            const Window& win,
            std::span<const int> y_shape,
            float* y,
            std::vector<float>* patches);
// DEPTHWISE_CONV_2D with depth multiplier 1: weights 1 x KH x KW x C, bias C or null.
void DepthwiseConv2d(const float* x,
                     std::span<const int> x_shape,
                     const float* weights,
                     const float* bias,
                     const Window& win,
                     std::span<const int> y_shape,
                     float* y);
void MaxPool2d(const float* x,
               std::span<const int> x_shape,
               const Window& win,
               std::span<const int> y_shape,
               float* y);
// ADD of two tensors of one shape (no broadcasting).
void Add(const float* x, const float* z, int64_t n, float* y);
// FULLY_CONNECTED: y (batch x out) = x (batch x in) weights^T (+ bias), weights out x in.
void FullyConnected(const float* x,
                    int64_t batch,
                    const float* weights,
                    int out,
                    int in,
                    const float* bias,
                    float* y);
void Logistic(const float* x, int64_t n, float* y);
// MEAN over H and W: y has C elements.
void MeanHW(const float* x, std::span<const int> x_shape, float* y);
// The fused activation of TFLite's ActivationFunctionType (0 none, 1 RELU, 2 RELU_N1_TO_1,
// 3 RELU6, 4 TANH), in place.
void Activate(int activation, float* v, size_t n);

}  // namespace handdb::tflite
