#include "nn/tflite_xnnpack.h"

#include <xnnpack.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <mutex>
#include <string>
#include <utility>

namespace handdb::tflite {
namespace {

using XnnGraph = TfliteModel::Graph;

// XNNPACK's aligned blocks (packed weights, the runtimes' activations: 16 MB for the full
// landmark model) in huge pages, as the model's own weights (base/huge_pages.h). Its unaligned
// blocks are mostly small (operator and value records), but the convolutions' indirection
// buffers, made when a runtime is set up, were ~400 page faults of a load in small pages: blocks
// from kHugeFrom bytes come from huge pages too. Each unaligned block starts with a header of its
// size and kind, which Reallocate and Deallocate read; 16 bytes keep malloc's alignment.
constexpr size_t kHeaderBytes = 16;
constexpr size_t kHugeFrom = size_t{64} << 10;

struct BlockHeader {
  size_t bytes;
  size_t huge;
};
static_assert(sizeof(BlockHeader) == kHeaderBytes);

BlockHeader* HeaderOf(void* p) {
  return reinterpret_cast<BlockHeader*>(static_cast<char*>(p) - kHeaderBytes);
}

void* Allocate(void*, size_t bytes) {
  const bool huge = bytes >= kHugeFrom;
  void* base =
      huge ? AllocateHuge(bytes + kHeaderBytes, kHeaderBytes) : std::malloc(bytes + kHeaderBytes);
  if (base == nullptr) return nullptr;
  *static_cast<BlockHeader*>(base) = {bytes, huge ? size_t{1} : size_t{0}};
  return static_cast<char*>(base) + kHeaderBytes;
}
void Deallocate(void*, void* p) {
  if (p == nullptr) return;
  BlockHeader* h = HeaderOf(p);
  if (h->huge != 0) {
    FreeHuge(h);
  } else {
    std::free(h);
  }
}
void* Reallocate(void* context, void* p, size_t bytes) {
  if (p == nullptr) return Allocate(context, bytes);
  BlockHeader* h = HeaderOf(p);
  if (h->huge == 0 && bytes < kHugeFrom) {
    void* moved = std::realloc(h, bytes + kHeaderBytes);
    if (moved == nullptr) return nullptr;
    static_cast<BlockHeader*>(moved)->bytes = bytes;
    return static_cast<char*>(moved) + kHeaderBytes;
  }
  void* q = Allocate(context, bytes);
  if (q == nullptr) return nullptr;
  std::memcpy(q, p, std::min(h->bytes, bytes));
  Deallocate(context, p);
  return q;
}
void* AllocateAligned(void*, size_t alignment, size_t bytes) {
  return AllocateHuge(bytes, alignment);
}
void DeallocateAligned(void*, void* p) { FreeHuge(p); }

// XNNPACK's own state is set up once per process and kept: its status answers every later call.
xnn_status InitializeXnnpack() {
  static const xnn_allocator allocator = {
      nullptr, Allocate, Reallocate, Deallocate, AllocateAligned, DeallocateAligned};
  static const xnn_status status = xnn_initialize(&allocator);
  return status;
}

struct SubgraphDeleter {
  void operator()(xnn_subgraph_t s) const { xnn_delete_subgraph(s); }
};
struct RuntimeDeleter {
  void operator()(xnn_runtime_t r) const { xnn_delete_runtime(r); }
};
using SubgraphPtr = std::unique_ptr<xnn_subgraph, SubgraphDeleter>;
using RuntimePtr = std::unique_ptr<xnn_runtime, RuntimeDeleter>;

constexpr float kInf = std::numeric_limits<float>::infinity();

// The output clamp of TFLite's fused activation (0 none, 1 RELU, 2 RELU_N1_TO_1, 3 RELU6);
// false for TANH, which XNNPACK cannot fuse.
bool ClampRange(int activation, float* lo, float* hi) {
  switch (activation) {
    case 0:
      *lo = -kInf, *hi = kInf;
      return true;
    case 1:
      *lo = 0, *hi = kInf;
      return true;
    case 2:
      *lo = -1, *hi = 1;
      return true;
    case 3:
      *lo = 0, *hi = 6;
      return true;
    default:
      return false;
  }
}

// Explicit padding of one axis, TFLite's rule (Window): the total split with the smaller half
// before. Explicit rather than XNN_FLAG_TENSORFLOW_SAME_PADDING, so both backends use one rule.
void Pads(
    const Window& win, int in, int k, int stride, int out, uint32_t* before, uint32_t* after) {
  const int b = win.pad_before(in, k, stride);
  const int total = win.padding == Padding::kSame ? std::max((out - 1) * stride + k - in, 0) : 0;
  *before = static_cast<uint32_t>(b);
  *after = static_cast<uint32_t>(total - b);
}

// One XNNPACK subgraph of a checked graph. Value ids 0..tensors-1 are the graph's tensors
// (defined when an operator first names them); ids above are values XNNPACK needs in another
// shape than the file's (a MEAN's 1x1x1xC, a FULLY_CONNECTED's batch x out).
class SubgraphBuilder {
 public:
  explicit SubgraphBuilder(const XnnGraph& g) : g_(g), defined_(g.tensors.size(), false) {}

  Result<SubgraphPtr> Build() {
    xnn_subgraph_t raw = nullptr;
    if (xnn_create_subgraph(static_cast<uint32_t>(g_.tensors.size()), 0, &raw) !=
        xnn_status_success) {
      return Fail("xnn_create_subgraph failed");
    }
    sg_.reset(raw);
    for (const int o : g_.outputs) {
      if (g_.tensors[o].constant || o == g_.inputs[0] ||
          std::count(g_.outputs.begin(), g_.outputs.end(), o) != 1) {
        return Fail("an output that is a constant, the input, or listed twice");
      }
    }
    for (size_t k = 0; k < g_.ops.size(); ++k) {
      if (Status s = AddOp(k); !s.ok()) return s;
    }
    return std::move(sg_);
  }

 private:
  Status Fail(const std::string& m) const {
    return Status(StatusCode::kUnknownRequiredFeature, "XNNPACK: " + m);
  }
  Status Check(xnn_status s, size_t k, const char* call) const {
    if (s == xnn_status_success) return Status::Ok();
    return Fail(std::string(call) + " for operator " + std::to_string(k) + " returned status " +
                std::to_string(static_cast<int>(s)));
  }

  // Tensor t as an XNNPACK value: the graph's input and outputs external, constants with their
  // float values.
  Result<uint32_t> Value(int t) {
    if (t < 0) return XNN_INVALID_VALUE_ID;
    const uint32_t id = static_cast<uint32_t>(t);
    if (defined_[t]) return id;
    const XnnGraph::Tensor& tensor = g_.tensors[t];
    if (tensor.shape.size() > XNN_MAX_TENSOR_DIMS) return Fail("a tensor of more than 6 dims");
    uint32_t flags = 0;
    if (t == g_.inputs[0]) flags |= XNN_VALUE_FLAG_EXTERNAL_INPUT;
    if (std::find(g_.outputs.begin(), g_.outputs.end(), t) != g_.outputs.end()) {
      flags |= XNN_VALUE_FLAG_EXTERNAL_OUTPUT;
    }
    const std::vector<size_t> dims(tensor.shape.begin(), tensor.shape.end());
    const void* data = tensor.constant ? g_.Values(t).data() : nullptr;
    uint32_t out = 0;
    if (xnn_define_tensor_value(
            sg_.get(), xnn_datatype_fp32, dims.size(), dims.data(), data, id, flags, &out) !=
        xnn_status_success) {
      return Fail("xnn_define_tensor_value failed for tensor " + std::to_string(t));
    }
    defined_[t] = true;
    return out;
  }

  // A value only XNNPACK sees, of shape `dims`.
  Result<uint32_t> Internal(const std::vector<size_t>& dims) {
    uint32_t out = 0;
    if (xnn_define_tensor_value(sg_.get(),
                                xnn_datatype_fp32,
                                dims.size(),
                                dims.data(),
                                nullptr,
                                XNN_INVALID_VALUE_ID,
                                0,
                                &out) != xnn_status_success) {
      return Fail("xnn_define_tensor_value failed for an internal value");
    }
    return out;
  }

  // The value an operator that can only write `dims` writes for tensor t: t itself when its
  // shape is `dims`, else an internal value reshaped into t after the node (*reshape_from set).
  Result<uint32_t> OutputAs(int t, const std::vector<size_t>& dims, uint32_t* reshape_from) {
    *reshape_from = XNN_INVALID_VALUE_ID;
    const std::vector<int>& shape = g_.tensors[t].shape;
    if (std::equal(shape.begin(), shape.end(), dims.begin(), dims.end())) return Value(t);
    auto internal = Internal(dims);
    if (internal.ok()) *reshape_from = *internal;
    return internal;
  }
  Status ReshapeInto(uint32_t from, int t, size_t k) {
    if (from == XNN_INVALID_VALUE_ID) return Status::Ok();
    auto to = Value(t);
    if (!to.ok()) return to.status();
    const std::vector<size_t> dims(g_.tensors[t].shape.begin(), g_.tensors[t].shape.end());
    return Check(xnn_define_static_reshape(sg_.get(), dims.size(), dims.data(), from, *to, 0),
                 k,
                 "xnn_define_static_reshape");
  }

  Status AddOp(size_t k) {
    const XnnGraph::Op& op = g_.ops[k];
    float lo = 0, hi = 0;
    if (!ClampRange(op.activation, &lo, &hi)) {
      return Fail("operator " + std::to_string(k) + " has fused activation " +
                  std::to_string(op.activation) + ", which XNNPACK cannot fuse");
    }
    auto input = [&](size_t i) -> Result<uint32_t> {
      return i < op.in.size() ? Value(op.in[i]) : Result<uint32_t>(XNN_INVALID_VALUE_ID);
    };
    auto x = input(0);
    if (!x.ok()) return x.status();
    const XnnGraph::Tensor& xt = g_.tensors[op.in[0]];
    const XnnGraph::Tensor& yt = g_.tensors[op.out[0]];
    switch (op.code) {
      case kConv2d:
      case kDepthwiseConv2d: {
        auto w = input(1);
        auto b = input(2);
        auto y = Value(op.out[0]);
        if (!w.ok()) return w.status();
        if (!b.ok()) return b.status();
        if (!y.ok()) return y.status();
        const Window& win = op.win;
        uint32_t top = 0, bottom = 0, left = 0, right = 0;
        Pads(win, xt.shape[1], win.kh, win.stride_h, yt.shape[1], &top, &bottom);
        Pads(win, xt.shape[2], win.kw, win.stride_w, yt.shape[2], &left, &right);
        const auto kh = static_cast<uint32_t>(win.kh), kw = static_cast<uint32_t>(win.kw);
        const auto sh = static_cast<uint32_t>(win.stride_h),
                   sw = static_cast<uint32_t>(win.stride_w);
        if (op.code == kConv2d) {
          return Check(xnn_define_convolution_2d(sg_.get(),
                                                 top,
                                                 right,
                                                 bottom,
                                                 left,
                                                 kh,
                                                 kw,
                                                 sh,
                                                 sw,
                                                 1,
                                                 1,
                                                 1,
                                                 static_cast<size_t>(xt.shape[3]),
                                                 static_cast<size_t>(yt.shape[3]),
                                                 lo,
                                                 hi,
                                                 *x,
                                                 *w,
                                                 *b,
                                                 *y,
                                                 0),
                       k,
                       "xnn_define_convolution_2d");
        }
        return Check(xnn_define_depthwise_convolution_2d(sg_.get(),
                                                         top,
                                                         right,
                                                         bottom,
                                                         left,
                                                         kh,
                                                         kw,
                                                         sh,
                                                         sw,
                                                         1,
                                                         1,
                                                         1,
                                                         static_cast<size_t>(xt.shape[3]),
                                                         lo,
                                                         hi,
                                                         *x,
                                                         *w,
                                                         *b,
                                                         *y,
                                                         0),
                     k,
                     "xnn_define_depthwise_convolution_2d");
      }
      case kMaxPool2d: {
        // TFLite's SAME pools ignore the padded cells; XNNPACK's flag asks for exactly that.
        const Window& win = op.win;
        auto y = Value(op.out[0]);
        if (!y.ok()) return y.status();
        return Check(xnn_define_max_pooling_2d(
                         sg_.get(),
                         0,
                         0,
                         0,
                         0,
                         static_cast<uint32_t>(win.kh),
                         static_cast<uint32_t>(win.kw),
                         static_cast<uint32_t>(win.stride_h),
                         static_cast<uint32_t>(win.stride_w),
                         1,
                         1,
                         lo,
                         hi,
                         *x,
                         *y,
                         win.padding == Padding::kSame ? XNN_FLAG_TENSORFLOW_SAME_PADDING : 0),
                     k,
                     "xnn_define_max_pooling_2d");
      }
      case kAdd: {
        auto z = input(1);
        auto y = Value(op.out[0]);
        if (!z.ok()) return z.status();
        if (!y.ok()) return y.status();
        return Check(xnn_define_add2(sg_.get(), lo, hi, *x, *z, *y, 0), k, "xnn_define_add2");
      }
      case kFullyConnected: {
        auto w = input(1);
        auto b = input(2);
        if (!w.ok()) return w.status();
        if (!b.ok()) return b.status();
        const XnnGraph::Tensor& wt = g_.tensors[op.in[1]];
        const auto in = static_cast<size_t>(wt.shape[1]), out = static_cast<size_t>(wt.shape[0]);
        uint32_t from = XNN_INVALID_VALUE_ID;
        auto y = OutputAs(op.out[0], {static_cast<size_t>(xt.elements) / in, out}, &from);
        if (!y.ok()) return y.status();
        HANDDB_RETURN_IF_ERROR(
            Check(xnn_define_fully_connected(
                      sg_.get(), lo, hi, *x, *w, *b, *y, XNN_FLAG_TENSORFLOW_RESHAPE_2D),
                  k,
                  "xnn_define_fully_connected"));
        return ReshapeInto(from, op.out[0], k);
      }
      case kLogistic: {
        auto y = Value(op.out[0]);
        if (!y.ok()) return y.status();
        return Check(xnn_define_sigmoid(sg_.get(), *x, *y, 0), k, "xnn_define_sigmoid");
      }
      case kReshape: {
        auto y = Value(op.out[0]);
        if (!y.ok()) return y.status();
        const std::vector<size_t> dims(yt.shape.begin(), yt.shape.end());
        return Check(xnn_define_static_reshape(sg_.get(), dims.size(), dims.data(), *x, *y, 0),
                     k,
                     "xnn_define_static_reshape");
      }
      case kMean: {
        uint32_t from = XNN_INVALID_VALUE_ID;
        auto y = OutputAs(op.out[0], {1, 1, 1, static_cast<size_t>(xt.shape[3])}, &from);
        if (!y.ok()) return y.status();
        HANDDB_RETURN_IF_ERROR(
            Check(xnn_define_global_average_pooling_2d(sg_.get(), -kInf, kInf, *x, *y, 0),
                  k,
                  "xnn_define_global_average_pooling_2d"));
        return ReshapeInto(from, op.out[0], k);
      }
      default:
        return Fail("operator " + std::to_string(k) + " has builtin code " +
                    std::to_string(op.code) + ", which this executor does not map");
    }
  }

  const XnnGraph& g_;
  std::vector<bool> defined_;
  SubgraphPtr sg_;
};

// One runtime and the external buffers it is set up with, once: the input padded by
// XNN_EXTRA_BYTES (XNNPACK's kernels may read, never write, that far past a tensor).
struct Runtime {
  RuntimePtr runtime;
  std::vector<float> input;
  std::vector<std::vector<float>> outputs;
};

class XnnpackExecutor final : public Executor {
 public:
  explicit XnnpackExecutor(const XnnGraph& g) : g_(g) {}

  Result<std::unique_ptr<Runtime>> NewRuntime() const {
    auto sg = SubgraphBuilder(g_).Build();
    if (!sg.ok()) return sg.status();
    xnn_runtime_t raw = nullptr;
    // A null thread pool: each run on its caller's thread (callers run pictures in parallel).
    const xnn_status created = xnn_create_runtime_v2(sg->get(), nullptr, 0, &raw);
    if (created != xnn_status_success) {
      return Status(StatusCode::kUnknownRequiredFeature,
                    "XNNPACK: xnn_create_runtime_v2 returned status " +
                        std::to_string(static_cast<int>(created)));
    }
    auto r = std::make_unique<Runtime>();
    r->runtime.reset(raw);
    const int64_t in_elements = g_.tensors[g_.inputs[0]].elements;
    r->input.assign(static_cast<size_t>(in_elements) + XNN_EXTRA_BYTES / sizeof(float), 0.0f);
    std::vector<xnn_external_value> external;
    external.push_back({static_cast<uint32_t>(g_.inputs[0]), r->input.data()});
    for (const int o : g_.outputs) {
      r->outputs.emplace_back(static_cast<size_t>(g_.tensors[o].elements) +
                              XNN_EXTRA_BYTES / sizeof(float));
      external.push_back({static_cast<uint32_t>(o), r->outputs.back().data()});
    }
    const xnn_status setup = xnn_setup_runtime(r->runtime.get(), external.size(), external.data());
    if (setup != xnn_status_success) {
      return Status(
          StatusCode::kUnknownRequiredFeature,
          "XNNPACK: xnn_setup_runtime returned status " + std::to_string(static_cast<int>(setup)));
    }
    return r;
  }

  void Keep(std::unique_ptr<Runtime> r) const {
    std::lock_guard<std::mutex> lock(mutex_);
    idle_.push_back(std::move(r));
  }

  std::vector<std::vector<float>> Run(std::span<const float> input) const override {
    std::unique_ptr<Runtime> r;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!idle_.empty()) {
        r = std::move(idle_.back());
        idle_.pop_back();
      }
    }
    if (r == nullptr) {
      // Every runtime is busy: another one, as the first was made at load.
      auto made = NewRuntime();
      THROW_CHECK_MSG(made.ok(), made.status().ToString());
      r = std::move(made).value();
    }
    std::copy(input.begin(), input.end(), r->input.begin());
    const xnn_status invoked = xnn_invoke_runtime(r->runtime.get());
    THROW_CHECK_MSG(invoked == xnn_status_success,
                    "xnn_invoke_runtime returned status " << static_cast<int>(invoked));
    std::vector<std::vector<float>> out;
    for (size_t i = 0; i < g_.outputs.size(); ++i) {
      const auto n = static_cast<size_t>(g_.tensors[g_.outputs[i]].elements);
      out.emplace_back(r->outputs[i].begin(), r->outputs[i].begin() + static_cast<ptrdiff_t>(n));
    }
    Keep(std::move(r));
    return out;
  }

 private:
  const XnnGraph& g_;
  mutable std::mutex mutex_;
  mutable std::vector<std::unique_ptr<Runtime>> idle_;
};

}  // namespace

Result<std::unique_ptr<Executor>> NewXnnpackExecutor(const TfliteModel::Graph& graph) {
  if (const xnn_status s = InitializeXnnpack(); s != xnn_status_success) {
    return Status(
        StatusCode::kUnknownRequiredFeature,
        "XNNPACK: xnn_initialize returned status " + std::to_string(static_cast<int>(s)) +
            (s == xnn_status_unsupported_hardware ? " (this CPU lacks its instructions)" : ""));
  }
  auto executor = std::make_unique<XnnpackExecutor>(graph);
  auto first = executor->NewRuntime();
  if (!first.ok()) return first.status();
  executor->Keep(std::move(first).value());
  return std::unique_ptr<Executor>(std::move(executor));
}

}  // namespace handdb::tflite
