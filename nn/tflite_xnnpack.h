// The XNNPACK executor of a checked TFLite graph (nn/tflite_graph.h): each operator becomes an
// XNNPACK subgraph node, and a runtime made from the subgraph (weights packed, buffers planned)
// runs it. Runtimes are not safe to run concurrently, so the executor keeps a pool: a caller
// takes an idle one or, when all are busy, makes another (each holds its own packed weights).
// Compiled only when XNNPACK is found (HANDDB_XNNPACK in the top-level CMakeLists.txt).
#pragma once

#include <memory>

#include "base/status.h"
#include "nn/tflite_graph.h"

namespace handdb::tflite {

// An executor of `graph`, which must outlive it (the runtimes read its constants), with one
// runtime made. kUnknownRequiredFeature: XNNPACK does not run on this CPU, or lacks an operator
// or a fused activation of the graph (named); the portable kernels can still run it.
Result<std::unique_ptr<Executor>> NewXnnpackExecutor(const TfliteModel::Graph& graph);

}  // namespace handdb::tflite
