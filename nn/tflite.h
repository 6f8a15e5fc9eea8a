// A small TensorFlow Lite runtime: float32 inference of the operators a MobileNet-style
// landmark network uses (CONV_2D, DEPTHWISE_CONV_2D, ADD, FULLY_CONNECTED, LOGISTIC, MEAN over
// H and W, MAX_POOL_2D, DEQUANTIZE of float16 weights, RESHAPE). Debian 12 packages no TFLite
// runtime, and OpenCV 4.6's dnn module does not read .tflite files; this reads the flatbuffer
// itself (docs/photo.md, "Hand landmarks"). Every offset, size and shape in the file is checked
// at load: a truncated or hostile file is an error naming the file, never a crash, and Run()
// only indexes with shapes validated against each operator.
//
// The checked graph then runs on one of two backends (TfliteBackend): XNNPACK, the kernels
// TFLite itself uses (the full landmark model in a few ms on one core; its weights are packed
// once, at load), or handdb's portable kernels (im2col + Eigen products, ~10x slower),
// used where XNNPACK is not built in, where the CPU lacks its instructions, or when asked for
// with HANDDB_NN_BACKEND=portable. The two agree to float rounding (XNNPACK sums in another
// order), not bit for bit.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"

namespace handdb {

// The kernels a model runs on.
enum class TfliteBackend {
  // XNNPACK when it can run the model, else portable; the environment variable HANDDB_NN_BACKEND
  // (portable or xnnpack) chooses instead when set.
  kDefault,
  kPortable,  // handdb's own kernels
  kXnnpack,   // XNNPACK where it can run the model (built in, CPU supported, every operator
              // mapped), else portable
};

class TfliteModel {
 public:
  // Reads and validates `path` (at most 256 MiB), then prepares the backend. Errors: kNotFound,
  // kIoError, kBadMagic (not a TFLite flatbuffer), kTruncated / kBadLayout (offsets outside the
  // file), kSizeMismatch (shapes that disagree), kUnknownRequiredFeature (an operator, option or
  // type this interpreter does not implement, named), kInvalidArgument (HANDDB_NN_BACKEND set to
  // something else than portable or xnnpack).
  static Result<TfliteModel> Load(const std::filesystem::path& path,
                                  TfliteBackend backend = TfliteBackend::kDefault);

  TfliteModel(TfliteModel&&) noexcept;
  TfliteModel& operator=(TfliteModel&&) noexcept;
  ~TfliteModel();

  // The first input's shape (NHWC for images) and the outputs' element counts.
  const std::vector<int>& input_shape() const;
  std::vector<size_t> output_sizes() const;
  // Multiply-adds of one Run (convolutions and products; other operators count one per output
  // element): 3.3e8 for the full landmark model.
  int64_t multiply_adds() const;
  // The backend Run uses: kPortable or kXnnpack.
  TfliteBackend backend() const;

  // Runs the graph on `input` (the first input tensor, row-major, input_shape()'s element
  // count); returns one vector per graph output. Thread-safe: each call has its own buffers.
  std::vector<std::vector<float>> Run(std::span<const float> input) const;
  // The same with buffers kept between calls (one Workspace per thread): no allocation, and no
  // page faults, after the first call. On XNNPACK the buffers are those of a runtime the model
  // keeps (one per concurrent caller, reused), and the workspace stays empty.
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
