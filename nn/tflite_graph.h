// The checked graph of a TFLite model (nn/tflite.h), as TfliteModel::Load leaves it: every
// tensor's shape and constant values, and the operators in the order of execution, each checked
// against its tensors' shapes. Internal to nn/: the portable kernels (nn/tflite_ops.h) and the
// XNNPACK executor (nn/tflite_xnnpack.h) both run it.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "base/huge_pages.h"
#include "nn/tflite.h"
#include "nn/tflite_ops.h"

namespace handdb {
namespace tflite {

// The builtin operators this runtime reads (tensorflow/lite/schema/schema.fbs's BuiltinOperator).
enum BuiltinOp {
  kAdd = 0,
  kConv2d = 3,
  kDepthwiseConv2d = 4,
  kDequantize = 6,
  kFullyConnected = 9,
  kLogistic = 14,
  kMaxPool2d = 17,
  kReshape = 22,
  kMean = 40,
};
enum TensorType { kFloat32 = 0, kFloat16 = 1, kInt32 = 2 };

// A second way to run a checked graph, with kernels of its own; built once at load. Run is
// thread-safe.
class Executor {
 public:
  virtual ~Executor() = default;
  virtual std::vector<std::vector<float>> Run(std::span<const float> input) const = 0;
};

}  // namespace tflite

struct TfliteModel::Graph {
  struct Tensor {
    std::vector<int> shape;
    int64_t elements = 1;
    int type = tflite::kFloat32;
    bool constant = false;
    // Constants (float16 weights converted at load), in huge pages (base/huge_pages.h). Read them
    // through Graph::Values: a folded DEQUANTIZE moves its input's here.
    std::vector<float, HugePageAllocator<float>> values;
    int folded_into = -1;   // a float16 constant: the DEQUANTIZE output that holds its values
    std::vector<int> ints;  // int32 constants (MEAN's axes, RESHAPE's shape)
  };
  struct Op {
    int code = 0;
    std::vector<int> in, out;
    tflite::Window win;
    int activation = 0;
    bool keep_dims = false;
  };
  // Constant t's float values (followed through the DEQUANTIZEs that moved them: each writes a
  // tensor written by no earlier operator, so the chain ends).
  const std::vector<float, HugePageAllocator<float>>& Values(int t) const {
    while (tensors[t].folded_into >= 0) t = tensors[t].folded_into;
    return tensors[t].values;
  }

  std::vector<Tensor> tensors;
  std::vector<Op> ops;
  std::vector<int> inputs, outputs;
  std::vector<int> last_use;  // per tensor: the last op that reads it (-1: none / output)
  // Per non-constant tensor: the workspace buffer it lives in. Buffers are shared by tensors
  // whose lives do not overlap (the full landmark model needs 4 instead of 166 tensors' worth).
  std::vector<int> slot;
  int num_slots = 0;
  int64_t multiply_adds = 0;
  // Null: Run uses the portable kernels. Declared last, so it is destroyed before the constants
  // it may point to.
  std::unique_ptr<tflite::Executor> executor;
};

}  // namespace handdb
