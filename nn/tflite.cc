#include "nn/tflite.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <cpuid.h>
#include <immintrin.h>
#endif
#include <limits>
#include <optional>
#include <system_error>

#include "nn/tflite_graph.h"
#include "nn/tflite_ops.h"
#if HANDDB_HAVE_XNNPACK
#include "nn/tflite_xnnpack.h"
#endif

namespace handdb {
namespace {

// The flatbuffer layout of the TFLite schema (tensorflow/lite/schema/schema.fbs), by field
// index. Only what this interpreter reads.
enum ModelField { kModelOperatorCodes = 1, kModelSubgraphs = 2, kModelBuffers = 4 };
enum SubgraphField { kSgTensors = 0, kSgInputs = 1, kSgOutputs = 2, kSgOperators = 3 };
enum TensorField { kTensorShape = 0, kTensorType = 1, kTensorBuffer = 2 };
enum OperatorField { kOpOpcode = 0, kOpInputs = 1, kOpOutputs = 2, kOpOptions = 4 };
using enum tflite::BuiltinOp;
using enum tflite::TensorType;

constexpr size_t kMaxFileBytes = size_t{256} << 20;
constexpr int64_t kMaxTensorElements = int64_t{1} << 26;

const char* OpName(int code) {
  switch (code) {
    case kAdd:
      return "ADD";
    case kConv2d:
      return "CONV_2D";
    case kDepthwiseConv2d:
      return "DEPTHWISE_CONV_2D";
    case kDequantize:
      return "DEQUANTIZE";
    case kFullyConnected:
      return "FULLY_CONNECTED";
    case kLogistic:
      return "LOGISTIC";
    case kMaxPool2d:
      return "MAX_POOL_2D";
    case kReshape:
      return "RESHAPE";
    case kMean:
      return "MEAN";
    default:
      return "?";
  }
}

// Bounds-checked reads of a flatbuffer. Every accessor returns nullopt / an error flag instead
// of reading outside the file.
class Flat {
 public:
  explicit Flat(std::span<const uint8_t> b) : b_(b) {}

  template <typename T>
  std::optional<T> Read(size_t pos) const {
    if (pos > b_.size() || b_.size() - pos < sizeof(T)) return std::nullopt;
    T v;
    std::memcpy(&v, b_.data() + pos, sizeof(T));
    return v;
  }
  // A table at `pos`: where field `i` lies (0: absent), or nullopt when the vtable is broken.
  std::optional<size_t> Field(size_t table, int i) const {
    const auto soff = Read<int32_t>(table);
    if (!soff) return std::nullopt;
    const int64_t vt = static_cast<int64_t>(table) - *soff;
    if (vt < 0 || static_cast<uint64_t>(vt) >= b_.size()) return std::nullopt;
    const auto vt_size = Read<uint16_t>(static_cast<size_t>(vt));
    if (!vt_size || *vt_size < 4 || *vt_size % 2 != 0) return std::nullopt;
    const size_t slot = 4 + 2 * static_cast<size_t>(i);
    if (slot + 2 > *vt_size) return size_t{0};
    const auto off = Read<uint16_t>(static_cast<size_t>(vt) + slot);
    if (!off) return std::nullopt;
    return *off == 0 ? size_t{0} : table + *off;
  }
  // The target of an offset field (table, vector or string), or nullopt.
  std::optional<size_t> Deref(size_t at) const {
    const auto off = Read<uint32_t>(at);
    if (!off || *off == 0 || at + *off >= b_.size()) return std::nullopt;
    return at + *off;
  }
  size_t size() const { return b_.size(); }
  const uint8_t* data() const { return b_.data(); }

 private:
  std::span<const uint8_t> b_;
};

// Errors carry the file's name; `Fail` builds them in one place.
struct Parse {
  const Flat& f;
  std::string what;
  Status error;

  bool Fail(StatusCode code, const std::string& msg) {
    if (error.ok()) error = Status(code, what + ": " + msg);
    return false;
  }
  // Where field `field` of `table` lies (0: absent, or no table); false on a broken vtable.
  bool At(size_t table, int field, size_t* at, const char* name) {
    const auto pos = table == 0 ? std::optional<size_t>(0) : f.Field(table, field);
    if (!pos) return Fail(StatusCode::kBadLayout, std::string("broken vtable reading ") + name);
    *at = *pos;
    return true;
  }
  // Optional table field -> its table position (0: absent).
  bool Table(size_t table, int field, size_t* out, const char* name) {
    size_t at = 0;
    if (!At(table, field, &at, name)) return false;
    if (at == 0) {
      *out = 0;
      return true;
    }
    const auto t = f.Deref(at);
    if (!t) return Fail(StatusCode::kTruncated, std::string(name) + " points outside the file");
    *out = *t;
    return true;
  }
  // A vector field: its first element's position and length (length 0 when absent).
  bool Vector(
      size_t table, int field, size_t elem_size, size_t* first, uint32_t* n, const char* name) {
    size_t v = 0;
    if (!Table(table, field, &v, name)) return false;
    if (v == 0) {
      *first = 0;
      *n = 0;
      return true;
    }
    const auto len = f.Read<uint32_t>(v);
    if (!len || (f.size() - v - 4) / elem_size < *len) {
      return Fail(StatusCode::kTruncated, std::string(name) + " runs past the end of the file");
    }
    *first = v + 4;
    *n = *len;
    return true;
  }
  bool Ints(size_t table, int field, std::vector<int>* out, const char* name) {
    size_t first = 0;
    uint32_t n = 0;
    if (!Vector(table, field, 4, &first, &n, name)) return false;
    out->resize(n);
    for (uint32_t k = 0; k < n; ++k) (*out)[k] = *f.Read<int32_t>(first + 4 * k);
    return true;
  }
  bool Tables(size_t table, int field, std::vector<size_t>* out, const char* name) {
    size_t first = 0;
    uint32_t n = 0;
    if (!Vector(table, field, 4, &first, &n, name)) return false;
    out->resize(n);
    for (uint32_t k = 0; k < n; ++k) {
      const auto t = f.Deref(first + 4 * k);
      if (!t)
        return Fail(StatusCode::kTruncated, std::string(name) + " entry points outside the file");
      (*out)[k] = *t;
    }
    return true;
  }
  template <typename T>
  bool Scalar(size_t table, int field, T def, T* out, const char* name) {
    size_t at = 0;
    if (!At(table, field, &at, name)) return false;
    if (at == 0) {
      *out = def;
      return true;
    }
    const auto v = f.Read<T>(at);
    if (!v)
      return Fail(StatusCode::kTruncated, std::string(name) + " lies past the end of the file");
    *out = *v;
    return true;
  }
};

float HalfToFloat(uint16_t h) {
  const uint32_t sign = static_cast<uint32_t>(h & 0x8000) << 16;
  const uint32_t exp = (h >> 10) & 0x1f;
  uint32_t mant = h & 0x3ff;
  uint32_t bits = 0;
  if (exp == 0) {
    if (mant == 0) {
      bits = sign;
    } else {  // subnormal: normalise
      int e = -1;
      do {
        ++e;
        mant <<= 1;
      } while ((mant & 0x400) == 0);
      bits = sign | static_cast<uint32_t>(127 - 15 - e) << 23 | (mant & 0x3ff) << 13;
    }
  } else if (exp == 31) {
    bits = sign | 0x7f800000u | mant << 13;
  } else {
    bits = sign | (exp + 127 - 15) << 23 | mant << 13;
  }
  float f;
  std::memcpy(&f, &bits, sizeof(f));
  return f;
}

void HalvesToFloatsScalar(const uint8_t* src, int64_t n, float* dst) {
  for (int64_t i = 0; i < n; ++i) {
    uint16_t h;
    std::memcpy(&h, src + 2 * i, 2);
    dst[i] = HalfToFloat(h);
  }
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
// Eight halves per instruction: the full landmark model's 2.7 M weights in ~1 ms instead of ~9.
// F16C's conversion is exact, so the values are HalfToFloat's (a NaN stays a NaN).
__attribute__((target("f16c"))) void HalvesToFloatsF16c(const uint8_t* src, int64_t n, float* dst) {
  int64_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m128i h = _mm_loadu_si128(reinterpret_cast<const __m128i*>(src + 2 * i));
    _mm256_storeu_ps(dst + i, _mm256_cvtph_ps(h));
  }
  HalvesToFloatsScalar(src + 2 * i, n - i, dst + i);
}
#endif

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
// F16C and the AVX stores it is used with, and an OS that saves the ymm registers (CPUID leaf 1,
// XGETBV): what __builtin_cpu_supports("f16c") asks, which not every compiler's builtin knows.
bool CpuHasF16c() {
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  if (__get_cpuid(1, &eax, &ebx, &ecx, &edx) == 0) return false;
  if ((ecx & bit_F16C) == 0 || (ecx & bit_AVX) == 0 || (ecx & bit_OSXSAVE) == 0) return false;
  unsigned lo = 0, hi = 0;
  __asm__ volatile("xgetbv" : "=a"(lo), "=d"(hi) : "c"(0));
  return (lo & 6u) == 6u;
}
#endif

// n little-endian float16 values at `src` as float32.
void HalvesToFloats(const uint8_t* src, int64_t n, float* dst) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  static const bool f16c = CpuHasF16c();
  if (f16c) {
    HalvesToFloatsF16c(src, n, dst);
    return;
  }
#endif
  HalvesToFloatsScalar(src, n, dst);
}

}  // namespace

using tflite::Padding;
using tflite::Window;

TfliteModel::TfliteModel(std::unique_ptr<Graph> graph) : graph_(std::move(graph)) {}
TfliteModel::TfliteModel(TfliteModel&&) noexcept = default;
TfliteModel& TfliteModel::operator=(TfliteModel&&) noexcept = default;
TfliteModel::~TfliteModel() = default;

const std::vector<int>& TfliteModel::input_shape() const {
  return graph_->tensors[graph_->inputs[0]].shape;
}

int64_t TfliteModel::multiply_adds() const { return graph_->multiply_adds; }

std::vector<size_t> TfliteModel::output_sizes() const {
  std::vector<size_t> out;
  for (int t : graph_->outputs) out.push_back(static_cast<size_t>(graph_->tensors[t].elements));
  return out;
}

namespace {

// Checks one operator against its tensors' declared shapes, so Run() can index blindly.
bool CheckOp(const TfliteModel::Graph& g,
             size_t index,
             const TfliteModel::Graph::Op& op,
             Parse* p) {
  using Tensor = TfliteModel::Graph::Tensor;
  const std::string where =
      std::string("operator ") + std::to_string(index) + " (" + OpName(op.code) + ")";
  auto fail = [&](const std::string& m) {
    return p->Fail(StatusCode::kSizeMismatch, where + ": " + m);
  };
  auto tensor = [&](size_t k, bool input) -> const Tensor* {
    const std::vector<int>& ids = input ? op.in : op.out;
    if (k >= ids.size() || ids[k] < 0) return nullptr;
    return &g.tensors[ids[k]];
  };
  const Tensor* x = tensor(0, true);
  const Tensor* y = tensor(0, false);
  if (x == nullptr || y == nullptr || op.out.size() != 1)
    return fail("needs an input and one output");
  if (y->constant) return fail("writes a constant tensor");
  if (op.code != kDequantize && x->type != kFloat32) return fail("input is not float32");
  auto dims4 = [](const Tensor* t) { return t->shape.size() == 4 && t->shape[0] == 1; };
  // Weights and biases: constants with float values (float32, or float16 converted at load).
  auto float_constant = [&g](const Tensor* t) {
    return t != nullptr && t->constant &&
           static_cast<int64_t>(g.Values(static_cast<int>(t - g.tensors.data())).size()) ==
               t->elements;
  };
  switch (op.code) {
    case kConv2d:
    case kDepthwiseConv2d: {
      const Tensor* w = tensor(1, true);
      const Tensor* b = tensor(2, true);
      if (!dims4(x) || !dims4(y) || !float_constant(w) || w->shape.size() != 4) {
        return fail("expects 1xHxWxC tensors and constant 4-D weights");
      }
      const int c = x->shape[3];
      const int o = y->shape[3];
      if (op.code == kConv2d ? (w->shape[0] != o || w->shape[3] != c)
                             : (w->shape[0] != 1 || w->shape[3] != c || o != c)) {
        return fail("weights do not match the channels");
      }
      if (w->shape[1] != op.win.kh || w->shape[2] != op.win.kw) return fail("kernel size");
      if (b != nullptr && (!float_constant(b) || b->elements != o)) return fail("bias size");
      if (y->shape[1] != op.win.out(x->shape[1], op.win.kh, op.win.stride_h) ||
          y->shape[2] != op.win.out(x->shape[2], op.win.kw, op.win.stride_w)) {
        return fail("output size");
      }
      return true;
    }
    case kMaxPool2d:
      if (!dims4(x) || !dims4(y) || y->shape[3] != x->shape[3] ||
          y->shape[1] != op.win.out(x->shape[1], op.win.kh, op.win.stride_h) ||
          y->shape[2] != op.win.out(x->shape[2], op.win.kw, op.win.stride_w)) {
        return fail("shapes");
      }
      return true;
    case kAdd: {
      const Tensor* z = tensor(1, true);
      if (z == nullptr || z->type != kFloat32 || z->shape != x->shape ||
          y->elements != x->elements) {
        return fail("ADD needs two float32 inputs of the output's shape (no broadcasting)");
      }
      return true;
    }
    case kFullyConnected: {
      const Tensor* w = tensor(1, true);
      const Tensor* b = tensor(2, true);
      if (!float_constant(w) || w->shape.size() != 2 || w->shape[1] <= 0 ||
          x->elements % w->shape[1] != 0 ||
          y->elements != x->elements / w->shape[1] * w->shape[0] ||
          (b != nullptr && (!float_constant(b) || b->elements != w->shape[0]))) {
        return fail("shapes");
      }
      return true;
    }
    case kLogistic:
    case kReshape:
      if (y->elements != x->elements) return fail("element counts differ");
      return true;
    case kDequantize:
      if (!x->constant || x->type != kFloat16 || y->elements != x->elements) {
        return fail("only constant float16 -> float32 is supported");
      }
      return true;
    case kMean: {
      const Tensor* axes = tensor(1, true);
      if (!dims4(x) || axes == nullptr || !axes->constant || axes->ints != std::vector<int>{1, 2} ||
          y->elements != x->shape[3]) {
        return fail("only the mean over H and W of a 1xHxWxC tensor is supported");
      }
      return true;
    }
    default:
      return fail("unsupported");
  }
}

using Graph = TfliteModel::Graph;

// The model file's bytes, in huge pages like the weights (base/huge_pages.h).
using FileBytes = std::vector<uint8_t, HugePageAllocator<uint8_t>>;

// The whole file, after its size and identifier checks.
Result<FileBytes> ReadModelFile(const std::filesystem::path& path) {
  const std::string what = path.string();
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  switch (st.type()) {
    case std::filesystem::file_type::regular:
      break;
    case std::filesystem::file_type::not_found:
      return Status(StatusCode::kNotFound, what + ": no such model file");
    case std::filesystem::file_type::directory:
      return Status(StatusCode::kInvalidArgument, what + ": a directory, not a model file");
    case std::filesystem::file_type::fifo:
      return Status(StatusCode::kInvalidArgument, what + ": a FIFO, not a model file");
    case std::filesystem::file_type::character:
    case std::filesystem::file_type::block:
      return Status(StatusCode::kInvalidArgument, what + ": a device, not a model file");
    case std::filesystem::file_type::socket:
      return Status(StatusCode::kInvalidArgument, what + ": a socket, not a model file");
    default:
      return Status(StatusCode::kIoError,
                    what + ": cannot read the model file" + (ec ? ": " + ec.message() : ""));
  }
  const auto file_size = std::filesystem::file_size(path, ec);
  if (ec) return Status(StatusCode::kIoError, what + ": " + ec.message());
  if (file_size > kMaxFileBytes) {
    return Status(StatusCode::kOutOfRange,
                  what + ": " + std::to_string(file_size) +
                      " bytes, more than a landmark model's 256 MiB limit");
  }
  FileBytes bytes(file_size);
  {
    std::ifstream in(path, std::ios::binary);
    if (!in.read(reinterpret_cast<char*>(bytes.data()),
                 static_cast<std::streamsize>(bytes.size()))) {
      return Status(StatusCode::kIoError, what + ": cannot read the file");
    }
  }
  if (bytes.size() < 8 || std::memcmp(bytes.data() + 4, "TFL3", 4) != 0) {
    return Status(StatusCode::kBadMagic,
                  what + ": not a TensorFlow Lite model (no TFL3 identifier)");
  }
  return bytes;
}

// The tables of the flatbuffer this runtime reads: the model's operator codes and buffers, and
// its first subgraph's tensors and operators.
struct ModelTables {
  struct Buffer {
    size_t first = 0;  // where its bytes start in the file
    uint32_t n = 0;
  };
  std::vector<int> codes;  // builtin operator per operator code
  std::vector<Buffer> buffers;
  std::vector<size_t> tensors, ops;
};

// Parse: the model's root table down to the subgraph's tables; the graph's inputs and outputs.
Status ParseModelTables(Parse* p, ModelTables* m, Graph* g) {
  const Flat& f = p->f;
  const auto root = f.Deref(0);
  if (!root) {
    return Status(StatusCode::kTruncated, p->what + ": the root table lies outside the file");
  }
  std::vector<size_t> codes_t, subgraphs, buffers_t;
  if (!p->Tables(*root, kModelOperatorCodes, &codes_t, "operator codes") ||
      !p->Tables(*root, kModelSubgraphs, &subgraphs, "subgraphs") ||
      !p->Tables(*root, kModelBuffers, &buffers_t, "buffers")) {
    return p->error;
  }
  if (subgraphs.empty())
    return Status(StatusCode::kBadLayout, p->what + ": the model has no subgraph");
  for (size_t t : codes_t) {
    int8_t deprecated = 0;
    int32_t builtin = 0;
    if (!p->Scalar<int8_t>(t, 0, 0, &deprecated, "operator code") ||
        !p->Scalar<int32_t>(t, 3, 0, &builtin, "operator code")) {
      return p->error;
    }
    m->codes.push_back(std::max<int>(deprecated, builtin));
  }
  for (size_t t : buffers_t) {
    ModelTables::Buffer b;
    uint64_t offset = 0;
    if (!p->Vector(t, 0, 1, &b.first, &b.n, "buffer data") ||
        !p->Scalar<uint64_t>(t, 1, 0, &offset, "buffer offset")) {
      return p->error;
    }
    if (offset != 0) {
      return Status(StatusCode::kUnknownRequiredFeature,
                    p->what + ": buffers stored outside the flatbuffer are not supported");
    }
    m->buffers.push_back(b);
  }
  const size_t sg = subgraphs[0];
  if (!p->Tables(sg, kSgTensors, &m->tensors, "tensors") ||
      !p->Ints(sg, kSgInputs, &g->inputs, "inputs") ||
      !p->Ints(sg, kSgOutputs, &g->outputs, "outputs") ||
      !p->Tables(sg, kSgOperators, &m->ops, "operators")) {
    return p->error;
  }
  return Status::Ok();
}

// Parse: tensor k's shape and type, and its constant values (float16 converted to float32).
Status ParseTensor(Parse* p, const ModelTables& m, size_t k, Graph::Tensor* t) {
  const std::string& what = p->what;
  int8_t type = 0;
  uint32_t buffer = 0;
  if (!p->Ints(m.tensors[k], kTensorShape, &t->shape, "tensor shape") ||
      !p->Scalar<int8_t>(m.tensors[k], kTensorType, 0, &type, "tensor type") ||
      !p->Scalar<uint32_t>(m.tensors[k], kTensorBuffer, 0, &buffer, "tensor buffer")) {
    return p->error;
  }
  t->type = type;
  for (int d : t->shape) {
    if (d <= 0 || t->elements * d > kMaxTensorElements) {
      return Status(
          StatusCode::kOutOfRange,
          what + ": tensor " + std::to_string(k) + " has a dimension <= 0 or too many elements");
    }
    t->elements *= d;
  }
  if (buffer >= m.buffers.size()) {
    return Status(StatusCode::kBadLayout,
                  what + ": tensor " + std::to_string(k) + " names buffer " +
                      std::to_string(buffer) + " of " + std::to_string(m.buffers.size()));
  }
  const ModelTables::Buffer& b = m.buffers[buffer];
  if (b.n == 0) return Status::Ok();
  t->constant = true;
  const size_t elem = type == kFloat16 ? 2 : 4;
  if (type != kFloat32 && type != kFloat16 && type != kInt32) {
    return Status(StatusCode::kUnknownRequiredFeature,
                  what + ": tensor " + std::to_string(k) + " has type " + std::to_string(type) +
                      " (float32, float16 and int32 constants are supported)");
  }
  if (b.n != static_cast<uint64_t>(t->elements) * elem) {
    return Status(StatusCode::kSizeMismatch,
                  what + ": tensor " + std::to_string(k) + " holds " + std::to_string(b.n) +
                      " bytes for " + std::to_string(t->elements) + " elements");
  }
  const uint8_t* src = p->f.data() + b.first;
  if (type == kInt32) {
    t->ints.resize(t->elements);
    std::memcpy(t->ints.data(), src, b.n);
  } else if (type == kFloat16) {
    t->values.resize(t->elements);
    HalvesToFloats(src, t->elements, t->values.data());
  } else {
    t->values.resize(t->elements);
    std::memcpy(t->values.data(), src, b.n);
  }
  return Status::Ok();
}

// Every id names a tensor of the graph (or is -1, an absent optional input, when `optional`).
bool ValidIds(const std::vector<int>& ids, bool optional, int num_tensors) {
  return std::all_of(ids.begin(), ids.end(), [&](int i) {
    return (optional && i == -1) || (i >= 0 && i < num_tensors);
  });
}

// Parse: operator k's code, tensors and options, with the options this runtime implements.
Status ParseOperator(Parse* p, const ModelTables& m, size_t k, const Graph& g, Graph::Op* out) {
  const std::string& what = p->what;
  const int num_tensors = static_cast<int>(g.tensors.size());
  Graph::Op& op = *out;
  uint32_t opcode = 0;
  if (!p->Scalar<uint32_t>(m.ops[k], kOpOpcode, 0, &opcode, "operator") ||
      !p->Ints(m.ops[k], kOpInputs, &op.in, "operator inputs") ||
      !p->Ints(m.ops[k], kOpOutputs, &op.out, "operator outputs")) {
    return p->error;
  }
  if (opcode >= m.codes.size()) {
    return Status(StatusCode::kBadLayout,
                  what + ": operator " + std::to_string(k) + " names operator code " +
                      std::to_string(opcode));
  }
  op.code = m.codes[opcode];
  if (std::string_view(OpName(op.code)) == "?") {
    return Status(StatusCode::kUnknownRequiredFeature,
                  what + ": operator " + std::to_string(k) + " is builtin operator " +
                      std::to_string(op.code) + ", which this interpreter does not implement");
  }
  if (!ValidIds(op.in, true, num_tensors) || !ValidIds(op.out, false, num_tensors)) {
    return Status(StatusCode::kBadLayout,
                  what + ": operator " + std::to_string(k) + " names a tensor that does not exist");
  }
  if (op.out.size() != 1 || op.in.empty() || op.in[0] < 0) {
    return Status(StatusCode::kBadLayout,
                  what + ": operator " + std::to_string(k) + " has " +
                      std::to_string(op.in.size()) + " inputs and " +
                      std::to_string(op.out.size()) +
                      " outputs (every operator here reads a first input and writes one output)");
  }
  if (std::find(op.in.begin(), op.in.end(), op.out[0]) != op.in.end()) {
    return Status(StatusCode::kBadLayout,
                  what + ": operator " + std::to_string(k) + " writes one of its own inputs");
  }
  size_t opt = 0;
  if (!p->Table(m.ops[k], kOpOptions, &opt, "operator options")) return p->error;
  int8_t padding = 0, act = 0, keep = 0;
  int32_t dil_w = 1, dil_h = 1, mult = 1;
  bool ok = true;
  // Conv2DOptions, DepthwiseConv2DOptions and Pool2DOptions all start with padding, stride_w,
  // stride_h (fields 0-2).
  auto window = [&] {
    return p->Scalar<int8_t>(opt, 0, 0, &padding, "padding") &&
           p->Scalar<int32_t>(opt, 1, 1, &op.win.stride_w, "stride") &&
           p->Scalar<int32_t>(opt, 2, 1, &op.win.stride_h, "stride");
  };
  switch (op.code) {
    case kConv2d:
      ok = window() && p->Scalar<int8_t>(opt, 3, 0, &act, "activation") &&
           p->Scalar<int32_t>(opt, 4, 1, &dil_w, "dilation") &&
           p->Scalar<int32_t>(opt, 5, 1, &dil_h, "dilation");
      break;
    case kDepthwiseConv2d:
      ok = window() && p->Scalar<int32_t>(opt, 3, 1, &mult, "depth multiplier") &&
           p->Scalar<int8_t>(opt, 4, 0, &act, "activation") &&
           p->Scalar<int32_t>(opt, 5, 1, &dil_w, "dilation") &&
           p->Scalar<int32_t>(opt, 6, 1, &dil_h, "dilation");
      break;
    case kMaxPool2d:
      ok = window() && p->Scalar<int32_t>(opt, 3, 1, &op.win.kw, "filter width") &&
           p->Scalar<int32_t>(opt, 4, 1, &op.win.kh, "filter height") &&
           p->Scalar<int8_t>(opt, 5, 0, &act, "activation");
      break;
    case kAdd:
    case kFullyConnected:
      ok = p->Scalar<int8_t>(opt, 0, 0, &act, "activation");
      break;
    case kMean:
      ok = p->Scalar<int8_t>(opt, 0, 0, &keep, "keep_dims");
      break;
    default:
      break;
  }
  if (!ok) return p->error;
  if (op.code == kConv2d || op.code == kDepthwiseConv2d) {
    const auto& w =
        op.in.size() > 1 && op.in[1] >= 0 ? g.tensors[op.in[1]].shape : std::vector<int>{};
    if (w.size() == 4) {
      op.win.kh = w[1];
      op.win.kw = w[2];
    }
  }
  op.win.padding = padding == 1 ? Padding::kValid : Padding::kSame;
  op.activation = act;
  op.keep_dims = keep != 0;
  if (padding < 0 || padding > 1 || act < 0 || act > 4 || dil_w != 1 || dil_h != 1 || mult != 1 ||
      op.win.stride_w < 1 || op.win.stride_h < 1 || op.win.kw < 1 || op.win.kh < 1 ||
      op.win.stride_w > 64 || op.win.stride_h > 64) {
    return Status(StatusCode::kUnknownRequiredFeature,
                  what + ": operator " + std::to_string(k) + " (" + OpName(op.code) +
                      ") has options this interpreter does not implement (padding " +
                      std::to_string(padding) + ", activation " + std::to_string(act) +
                      ", dilation " + std::to_string(dil_w) + "x" + std::to_string(dil_h) +
                      ", depth multiplier " + std::to_string(mult) + ")");
  }
  return Status::Ok();
}

// Check: one non-constant input and at least one output, all of them tensors of the graph.
Status CheckGraphIo(const std::string& what, const Graph& g) {
  const int num_tensors = static_cast<int>(g.tensors.size());
  if (g.inputs.size() != 1 || g.outputs.empty() || !ValidIds(g.inputs, false, num_tensors) ||
      !ValidIds(g.outputs, false, num_tensors) || g.tensors[g.inputs[0]].constant) {
    return Status(StatusCode::kBadLayout,
                  what + ": the graph must have one non-constant input and at least one output");
  }
  return Status::Ok();
}

// Check: operator k reads only tensors computed before it (`ready`: the file's order is the order
// of execution, so Run() never reads a buffer it has not filled), writes a new one, and fits its
// tensors' shapes (CheckOp). Then adds it to the graph; a DEQUANTIZE is folded into a constant.
Status AddOperator(Parse* p, size_t k, Graph::Op op, std::vector<bool>* ready, Graph* g) {
  const std::string& what = p->what;
  if ((*ready)[op.out[0]]) {
    return Status(StatusCode::kBadLayout,
                  what + ": operator " + std::to_string(k) + " writes tensor " +
                      std::to_string(op.out[0]) +
                      ", which is an input, a constant or written before");
  }
  for (int i : op.in) {
    if (i >= 0 && !(*ready)[i]) {
      return Status(StatusCode::kBadLayout,
                    what + ": operator " + std::to_string(k) + " reads tensor " +
                        std::to_string(i) + " before any operator writes it");
    }
  }
  if (!CheckOp(*g, k, op, p)) return p->error;
  (*ready)[op.out[0]] = true;
  if (op.code == kDequantize) {
    // Constant folding: the output takes the float16 tensor's values (converted by
    // ParseTensor), moved rather than copied (11 MB for the full landmark model) unless another
    // DEQUANTIZE took them first; readers of either tensor find them through Graph::Values.
    Graph::Tensor& out = g->tensors[op.out[0]];
    Graph::Tensor& in = g->tensors[op.in[0]];
    if (in.folded_into < 0) {
      out.values = std::move(in.values);
      in.folded_into = op.out[0];
    } else {
      out.values = g->Values(op.in[0]);
    }
    out.constant = true;
    return Status::Ok();
  }
  g->ops.push_back(std::move(op));
  return Status::Ok();
}

// Multiply-adds of one Run: convolutions and products, one per output element for the rest.
int64_t CountMultiplyAdds(const Graph& g) {
  double work = 0;  // double: a hostile graph's counts could overflow int64
  for (const Graph::Op& op : g.ops) {
    const Graph::Tensor& x = g.tensors[op.in[0]];
    const Graph::Tensor& y = g.tensors[op.out[0]];
    int64_t per_output = 1;
    if (op.code == kConv2d) per_output = int64_t{op.win.kh} * op.win.kw * x.shape[3];
    if (op.code == kDepthwiseConv2d || op.code == kMaxPool2d)
      per_output = int64_t{op.win.kh} * op.win.kw;
    if (op.code == kFullyConnected) per_output = g.tensors[op.in[1]].shape[1];
    if (op.code == kMean) per_output = x.elements / std::max<int64_t>(1, y.elements);
    work += static_cast<double>(y.elements) * static_cast<double>(per_output);
  }
  return work < 9e18 ? static_cast<int64_t>(work) : std::numeric_limits<int64_t>::max();
}

// Plan: each tensor's last reader, and the workspace buffers by liveness. An operator's output
// takes a free buffer before its inputs' buffers are released, so no operator reads and writes
// one buffer.
void PlanBuffers(Graph* g) {
  const int num_tensors = static_cast<int>(g->tensors.size());
  g->last_use.assign(num_tensors, -1);
  for (size_t k = 0; k < g->ops.size(); ++k) {
    for (int i : g->ops[k].in) {
      if (i >= 0) g->last_use[i] = static_cast<int>(k);
    }
  }
  for (int o : g->outputs) g->last_use[o] = std::numeric_limits<int>::max();
  g->slot.assign(num_tensors, -1);
  std::vector<int> free_slots;
  auto take = [&](int t) {
    if (g->tensors[t].constant || g->slot[t] >= 0) return;
    if (free_slots.empty()) {
      g->slot[t] = g->num_slots++;
    } else {
      g->slot[t] = free_slots.back();
      free_slots.pop_back();
    }
  };
  take(g->inputs[0]);
  for (size_t k = 0; k < g->ops.size(); ++k) {
    take(g->ops[k].out[0]);
    for (int i : g->ops[k].in) {
      if (i >= 0 && g->slot[i] >= 0 && g->last_use[i] == static_cast<int>(k)) {
        free_slots.push_back(g->slot[i]);
        g->last_use[i] = -2;  // released once, even when an operator reads it twice
      }
    }
  }
}

// kDefault resolved: HANDDB_NN_BACKEND when set, else XNNPACK.
Result<TfliteBackend> ChooseBackend(TfliteBackend asked) {
  if (asked != TfliteBackend::kDefault) return asked;
  const char* env = std::getenv("HANDDB_NN_BACKEND");
  const std::string_view name = env == nullptr ? "" : env;
  if (name.empty() || name == "xnnpack") return TfliteBackend::kXnnpack;
  if (name == "portable") return TfliteBackend::kPortable;
  return Status(StatusCode::kInvalidArgument,
                "HANDDB_NN_BACKEND=" + std::string(name) + ": expected portable or xnnpack");
}

}  // namespace

Result<TfliteModel> TfliteModel::Load(const std::filesystem::path& path, TfliteBackend backend) {
  const std::string what = path.string();
  auto chosen = ChooseBackend(backend);
  if (!chosen.ok()) return chosen.status();
  auto bytes = ReadModelFile(path);
  if (!bytes.ok()) return bytes.status();
  const Flat f(*bytes);
  Parse p{f, what, {}};
  auto g = std::make_unique<Graph>();

  // Parse the flatbuffer into tables, then the tensors.
  ModelTables m;
  HANDDB_RETURN_IF_ERROR(ParseModelTables(&p, &m, g.get()));
  for (size_t k = 0; k < m.tensors.size(); ++k) {
    Graph::Tensor t;
    HANDDB_RETURN_IF_ERROR(ParseTensor(&p, m, k, &t));
    g->tensors.push_back(std::move(t));
  }

  // Check the graph, operator by operator in the order of execution.
  HANDDB_RETURN_IF_ERROR(CheckGraphIo(what, *g));
  std::vector<bool> ready(g->tensors.size(), false);
  for (size_t t = 0; t < g->tensors.size(); ++t) ready[t] = g->tensors[t].constant;
  ready[g->inputs[0]] = true;
  for (size_t k = 0; k < m.ops.size(); ++k) {
    Graph::Op op;
    HANDDB_RETURN_IF_ERROR(ParseOperator(&p, m, k, *g, &op));
    HANDDB_RETURN_IF_ERROR(AddOperator(&p, k, std::move(op), &ready, g.get()));
  }
  for (int o : g->outputs) {
    if (!ready[o]) {
      return Status(StatusCode::kBadLayout,
                    what + ": graph output tensor " + std::to_string(o) + " is never computed");
    }
  }

  // Plan the buffers Run() uses.
  g->multiply_adds = CountMultiplyAdds(*g);
  PlanBuffers(g.get());
#if HANDDB_HAVE_XNNPACK
  // A graph XNNPACK cannot run (an operator or activation it lacks, a CPU without its
  // instructions) runs on the portable kernels: same results up to rounding, only slower.
  if (*chosen == TfliteBackend::kXnnpack) {
    auto executor = tflite::NewXnnpackExecutor(*g);
    if (executor.ok()) g->executor = std::move(executor).value();
  }
#endif
  return TfliteModel(std::move(g));
}

TfliteBackend TfliteModel::backend() const {
  return graph_->executor != nullptr ? TfliteBackend::kXnnpack : TfliteBackend::kPortable;
}

std::vector<std::vector<float>> TfliteModel::Run(std::span<const float> input) const {
  Workspace ws;
  return Run(input, &ws);
}

std::unique_ptr<TfliteModel::Workspace> TfliteModel::NewWorkspace() const {
  return std::make_unique<Workspace>();
}

std::vector<std::vector<float>> TfliteModel::Run(std::span<const float> input,
                                                 Workspace* ws) const {
  const Graph& g = *graph_;
  THROW_CHECK_EQ(input.size(), static_cast<size_t>(g.tensors[g.inputs[0]].elements));
  if (g.executor != nullptr) return g.executor->Run(input);
  ws->slots.resize(g.num_slots);
  auto value = [&](int t) -> const float* {
    return g.tensors[t].constant ? g.Values(t).data() : ws->slots[g.slot[t]].data();
  };
  ws->slots[g.slot[g.inputs[0]]].assign(input.begin(), input.end());
  for (size_t k = 0; k < g.ops.size(); ++k) {
    const Graph::Op& op = g.ops[k];
    const Graph::Tensor& xt = g.tensors[op.in[0]];
    const Graph::Tensor& yt = g.tensors[op.out[0]];
    // Sized, not cleared: every operator below writes each output element before reading it.
    std::vector<float>& y = ws->slots[g.slot[op.out[0]]];
    y.resize(yt.elements);
    const float* x = value(op.in[0]);
    const float* bias = op.in.size() > 2 && op.in[2] >= 0 ? value(op.in[2]) : nullptr;
    switch (op.code) {
      case kConv2d:
        tflite::Conv2d(
            x, xt.shape, value(op.in[1]), bias, op.win, yt.shape, y.data(), &ws->patches);
        break;
      case kDepthwiseConv2d:
        tflite::DepthwiseConv2d(x, xt.shape, value(op.in[1]), bias, op.win, yt.shape, y.data());
        break;
      case kMaxPool2d:
        tflite::MaxPool2d(x, xt.shape, op.win, yt.shape, y.data());
        break;
      case kAdd:
        tflite::Add(x, value(op.in[1]), yt.elements, y.data());
        break;
      case kFullyConnected: {
        const Graph::Tensor& wt = g.tensors[op.in[1]];
        const int o = wt.shape[0], in = wt.shape[1];
        tflite::FullyConnected(x, xt.elements / in, value(op.in[1]), o, in, bias, y.data());
        break;
      }
      case kLogistic:
        tflite::Logistic(x, yt.elements, y.data());
        break;
      case kReshape:
        std::copy(x, x + yt.elements, y.begin());
        break;
      case kMean:
        tflite::MeanHW(x, xt.shape, y.data());
        break;
      default:
        THROW_CHECK_MSG(false, "operator " << op.code << " passed the load checks");
    }
    tflite::Activate(op.activation, y.data(), y.size());
  }
  std::vector<std::vector<float>> out;
  for (int o : g.outputs) {
    const float* v = value(o);
    out.emplace_back(v, v + g.tensors[o].elements);
  }
  return out;
}

}  // namespace handdb
