// A small TensorFlow Lite interpreter: float32 inference of the operators a MobileNet-style
// landmark network uses (CONV_2D, DEPTHWISE_CONV_2D, ADD, FULLY_CONNECTED, LOGISTIC, MEAN over
// H and W, MAX_POOL_2D, DEQUANTIZE of float16 weights, RESHAPE). Debian 12 packages no TFLite
// runtime, and OpenCV 4.6's dnn module does not read .tflite files; this reads the flatbuffer
// itself (docs/query.md, "Hand landmarks"). Every offset, size and shape in the file is checked
// at load: a truncated or hostile file is an error naming the file, never a crash, and Run()
// only indexes with shapes validated against each operator.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"

namespace handdb {

class TfliteModel {
 public:
  // Reads and validates `path` (at most 256 MiB). Errors: kNotFound, kIoError, kBadMagic (not a
  // TFLite flatbuffer), kTruncated / kBadLayout (offsets outside the file), kSizeMismatch
  // (shapes that disagree), kUnknownRequiredFeature (an operator, option or type this
  // interpreter does not implement, named).
  static Result<TfliteModel> Load(const std::filesystem::path& path);

  TfliteModel(TfliteModel&&) noexcept;
  TfliteModel& operator=(TfliteModel&&) noexcept;
  ~TfliteModel();

  // The first input's shape (NHWC for images) and the outputs' element counts.
  const std::vector<int>& input_shape() const;
  std::vector<size_t> output_sizes() const;
  // Multiply-adds of one Run (convolutions and products; other operators count one per output
  // element): 3.3e8 for the full landmark model.
  int64_t multiply_adds() const;

  // Runs the graph on `input` (the first input tensor, row-major, input_shape()'s element
  // count); returns one vector per graph output. Thread-safe: each call has its own buffers.
  std::vector<std::vector<float>> Run(std::span<const float> input) const;
  // The same with buffers kept between calls (one Workspace per thread): no allocation, and no
  // page faults, after the first call.
  struct Workspace {
    std::vector<std::vector<float>> slots;  // the graph's buffers (shared by liveness)
    std::vector<float> patches;             // im2col rows of the convolutions
  };
  std::unique_ptr<Workspace> NewWorkspace() const;
  std::vector<std::vector<float>> Run(std::span<const float> input, Workspace* workspace) const;

  struct Graph;

 private:
  explicit TfliteModel(std::unique_ptr<Graph> graph);
  std::unique_ptr<Graph> graph_;
};

}  // namespace handdb
