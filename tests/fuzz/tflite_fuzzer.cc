// libFuzzer target for the TFLite model reader (nn/tflite.h): the bytes as a model file
// through TfliteModel::Load (flatbuffer offsets, vector lengths, tensor shapes and buffers, each
// operator against its tensors), and a model that loads is run once on zeros when it is small
// enough to run within the fuzzer's time limit: Run() must stay inside the shapes Load checked
// (ASan), and give one output per graph output of its declared size. Seeds (corpus/tflite): the
// three one-operator-family models of tests/data/tflite (make_models.py).
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "fuzz_file.h"
#include "nn/tflite.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = handdb::fuzz::WriteInput(data, size, "model.tflite");
  auto model = handdb::TfliteModel::Load(path);
  if (!model.ok() || model->multiply_adds() > 2'000'000) return 0;
  int64_t elements = 1;
  for (int d : model->input_shape()) elements *= d;
  if (elements > 1'000'000) return 0;
  const std::vector<float> input(static_cast<size_t>(elements), 0.0f);
  const auto out = model->Run(input);
  const auto sizes = model->output_sizes();
  if (out.size() != sizes.size()) std::abort();
  for (size_t i = 0; i < out.size(); ++i) {
    if (out[i].size() != sizes[i]) std::abort();
  }
  return 0;
}
