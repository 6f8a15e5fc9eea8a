// The landmark network's cost on each backend of the TFLite runtime (nn/tflite.h), in one run:
// the median time of a load followed by the first run, each in a fresh process (what one
// `handdb query` of a photo pays: a process's first touch of its memory is part of it), the
// median warm run, and the ratio of the portable kernels' times to XNNPACK's. Wall and CPU
// time of the one thread; pin it (taskset -c 0) for numbers that compare, and read the CPU
// times on a shared machine.
//
//   landmark_bench [--model PATH] [--loads N] [--runs N]
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "base/repo_root.h"
#include "bench/bench_args.h"
#include "bench/median.h"
#include "nn/tflite.h"

namespace handdb {
namespace {

using Clock = std::chrono::steady_clock;

using bench::Median;

// Wall and thread CPU milliseconds since construction.
struct Stopwatch {
  Clock::time_point wall0 = Clock::now();
  double cpu0 = CpuMs();
  static double CpuMs() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) / 1e6;
  }
  double Wall() const {
    return std::chrono::duration<double, std::milli>(Clock::now() - wall0).count();
  }
  double Cpu() const { return CpuMs() - cpu0; }
};

struct Args {
  std::string model =
      (RepoRoot() / "third_party" / "assets" / "mediapipe-hands" / "hand_landmark_full.tflite")
          .string();
  int loads = 7;
  int runs = 30;
};

struct Timing {
  double load_first_wall = 0, load_first_cpu = 0;  // medians of load + first run
  double warm_wall = 0, warm_cpu = 0;              // medians of warm runs
  bool ok = false;
};

const char* Name(TfliteBackend backend) {
  return backend == TfliteBackend::kXnnpack ? "xnnpack" : "portable";
}

std::vector<float> Input(const TfliteModel& m) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<float> x(static_cast<size_t>(m.input_shape()[1]) * m.input_shape()[2] * 3);
  for (float& v : x) v = u(rng);
  return x;
}

// Load + first run in a child process: {wall ms, CPU ms}, or {-1, -1} when the model does not
// load on `backend`.
std::pair<double, double> ColdLoad(const Args& args, TfliteBackend backend) {
  int fds[2];
  if (::pipe(fds) != 0) return {-1, -1};
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(fds[0]);
    double out[2] = {-1, -1};
    const Stopwatch watch;
    auto m = TfliteModel::Load(args.model, backend);
    if (m.ok() && m->backend() == backend) {
      const auto first = m->Run(Input(*m));
      out[0] = watch.Wall();
      out[1] = watch.Cpu();
    } else if (!m.ok()) {
      std::fprintf(stderr, "landmark_bench: %s\n", m.status().ToString().c_str());
    }
    const bool written = ::write(fds[1], out, sizeof(out)) == static_cast<ssize_t>(sizeof(out));
    ::_exit(written ? 0 : 1);
  }
  ::close(fds[1]);
  double in[2] = {-1, -1};
  const bool got = pid > 0 && ::read(fds[0], in, sizeof(in)) == static_cast<ssize_t>(sizeof(in));
  ::close(fds[0]);
  if (pid > 0) ::waitpid(pid, nullptr, 0);
  return got ? std::make_pair(in[0], in[1]) : std::make_pair(-1.0, -1.0);
}

bool Cold(const Args& args, TfliteBackend backend, Timing* t) {
  std::vector<double> wall, cpu;
  for (int i = 0; i < args.loads; ++i) {
    const auto [w, c] = ColdLoad(args, backend);
    if (w < 0) {
      std::fprintf(stderr, "landmark_bench: %s is not available here\n", Name(backend));
      return false;
    }
    wall.push_back(w);
    cpu.push_back(c);
  }
  t->load_first_wall = Median(wall);
  t->load_first_cpu = Median(cpu);
  return true;
}

void Warm(const Args& args, TfliteBackend backend, Timing* t) {
  auto m = TfliteModel::Load(args.model, backend);
  if (!m.ok()) return;
  const std::vector<float> x = Input(*m);
  auto ws = m->NewWorkspace();
  const auto first = m->Run(x, ws.get());
  std::vector<double> wall, cpu;
  for (int r = 0; r < args.runs; ++r) {
    const Stopwatch watch;
    const auto again = m->Run(x, ws.get());
    wall.push_back(watch.Wall());
    cpu.push_back(watch.Cpu());
  }
  t->warm_wall = Median(wall);
  t->warm_cpu = Median(cpu);
  std::printf(
      "%-9s load + first run %7.2f ms wall %7.2f ms CPU (median of %d processes)   "
      "warm run %7.2f ms wall %7.2f ms CPU (median of %d)\n",
      Name(backend),
      t->load_first_wall,
      t->load_first_cpu,
      args.loads,
      t->warm_wall,
      t->warm_cpu,
      args.runs);
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
  // Every cold load before any in this process, so each child starts from a fresh heap.
  Timing portable, xnnpack;
  portable.ok = Cold(args, TfliteBackend::kPortable, &portable);
  xnnpack.ok = Cold(args, TfliteBackend::kXnnpack, &xnnpack);
  if (!portable.ok) return 1;
  if (auto m = TfliteModel::Load(args.model); m.ok()) {
    std::printf("model: %s, %.3g multiply-adds per run\n",
                std::filesystem::path(args.model).filename().c_str(),
                static_cast<double>(m->multiply_adds()));
  }
  Warm(args, TfliteBackend::kPortable, &portable);
  if (xnnpack.ok) {
    Warm(args, TfliteBackend::kXnnpack, &xnnpack);
    std::printf(
        "portable / xnnpack: load + first run %.1fx wall %.1fx CPU, warm run %.1fx wall "
        "%.1fx CPU\n",
        portable.load_first_wall / xnnpack.load_first_wall,
        portable.load_first_cpu / xnnpack.load_first_cpu,
        portable.warm_wall / xnnpack.warm_wall,
        portable.warm_cpu / xnnpack.warm_cpu);
  }
  return 0;
}

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) { return handdb::Main(argc, argv); }
