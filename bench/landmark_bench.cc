// The landmark network's cost on each backend of the TFLite runtime (nn/tflite.h), in one run:
// the median time of a load followed by the first run (what one `handdb query` of a photo pays),
// the median warm run, and the ratio of the portable kernels' times to XNNPACK's. One thread;
// pin it (taskset -c 0) for numbers that compare.
//
//   landmark_bench [--model PATH] [--loads N] [--runs N]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "base/repo_root.h"
#include "bench/bench_args.h"
#include "nn/tflite.h"

namespace handdb {
namespace {

using Clock = std::chrono::steady_clock;

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

struct Args {
  std::string model =
      (RepoRoot() / "third_party" / "assets" / "mediapipe-hands" / "hand_landmark_full.tflite")
          .string();
  int loads = 5;
  int runs = 30;
};

struct Timing {
  double load_first_ms = 0;  // median of load + first run
  double warm_ms = 0;        // median warm run
  bool ok = false;
};

Timing Measure(const Args& args, TfliteBackend backend, const char* name) {
  Timing t;
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<double> load_first;
  std::vector<float> input;
  for (int i = 0; i < args.loads; ++i) {
    const auto t0 = Clock::now();
    auto m = TfliteModel::Load(args.model, backend);
    if (!m.ok()) {
      std::fprintf(stderr, "landmark_bench: %s\n", m.status().ToString().c_str());
      return t;
    }
    if (m->backend() != backend) {
      std::fprintf(stderr, "landmark_bench: %s is not available here\n", name);
      return t;
    }
    if (input.empty()) {
      input.resize(static_cast<size_t>(m->input_shape()[1]) * m->input_shape()[2] * 3);
      for (float& v : input) v = u(rng);
    }
    auto ws = m->NewWorkspace();
    const auto out = m->Run(input, ws.get());
    load_first.push_back(MsSince(t0));
    if (i + 1 < args.loads) continue;
    std::vector<double> warm;
    for (int r = 0; r < args.runs; ++r) {
      const auto t1 = Clock::now();
      const auto again = m->Run(input, ws.get());
      warm.push_back(MsSince(t1));
    }
    t.warm_ms = Median(warm);
    std::printf("%-9s %.3g multiply-adds per run\n", name, static_cast<double>(m->multiply_adds()));
  }
  t.load_first_ms = Median(load_first);
  t.ok = true;
  std::printf("%-9s load + first run %8.2f ms (median of %d)   warm run %8.2f ms (median of %d)\n",
              name,
              t.load_first_ms,
              args.loads,
              t.warm_ms,
              args.runs);
  return t;
}

int Main(int argc, char** argv) {
  Args args;
  CLI::App app{"landmark_bench: the landmark network on the portable kernels and on XNNPACK"};
  app.add_option("--model", args.model, "a .tflite landmark model")->capture_default_str();
  app.add_option("--loads", args.loads, "loads, each followed by a first run")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--runs", args.runs, "warm runs after the last load")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  if (const int code = bench::ParseBenchArgs(app, argc, argv); code >= 0) return code;
  const Timing portable = Measure(args, TfliteBackend::kPortable, "portable");
  const Timing xnnpack = Measure(args, TfliteBackend::kXnnpack, "xnnpack");
  if (!portable.ok) return 1;
  if (xnnpack.ok && xnnpack.load_first_ms > 0 && xnnpack.warm_ms > 0) {
    std::printf("portable / xnnpack: load + first run %.1fx, warm run %.1fx\n",
                portable.load_first_ms / xnnpack.load_first_ms,
                portable.warm_ms / xnnpack.warm_ms);
  }
  return 0;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) { return handdb::Main(argc, argv); }
