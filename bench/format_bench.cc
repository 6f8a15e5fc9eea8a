// Shard format benchmark: writes and reads a shard of synthetic views and prints rates
// against the raw rate of read()ing the same bytes in the same run (warm page cache).
//
//   format_bench [--views 100000] [--points 600] [--reps 3] [--dir /tmp]
//   format_bench --write-sample DB_DIR   # a small synthetic database (3 shards + manifest) to try
//                                        # handdb info / validate on
//
// Targets: sequential scan >= 50% of the raw read rate; file size <= 1.2 x raw payload
// (label fields + points). Prints medians over --reps repetitions.
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "format/manifest.h"
#include "format/shard_layout.h"
#include "format/shard_reader.h"
#include "format/shard_testing.h"
#include "format/shard_writer.h"
#include "format/validator.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

// The machine is shared, so rates are reported both by wall time and by this thread's CPU time
// (user + system, which excludes time spent waiting for a core; page faults and read() count).
struct Time {
  double wall = 0;
  double cpu = 0;
};

double ThreadCpu() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

Time Seconds(const std::function<void()>& fn) {
  const double c0 = ThreadCpu();
  const auto t0 = std::chrono::steady_clock::now();
  fn();
  return {std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
          ThreadCpu() - c0};
}

// Touches every point: sums its x and y coordinates (a plain loop, as a consumer would write).
int64_t TouchPoints(std::span<const PointQ> pts) {
  int64_t sx = 0;
  int64_t sy = 0;
  for (const PointQ& p : pts) {
    sx += p.x;
    sy += p.y;
  }
  return sx + sy;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

[[noreturn]] void Die(const std::string& what) {
  std::fprintf(stderr, "format_bench: %s\n", what.c_str());
  std::exit(1);
}

void Check(const Status& s) {
  if (!s.ok()) Die(s.ToString());
}

// read() the whole file into a 1 MiB buffer; returns a value derived from the bytes so the
// reads are not optimised away.
uint64_t RawRead(const fs::path& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) Die(path.string() + ": cannot open");
  std::vector<uint8_t> buf(1 << 20);
  uint64_t sum = 0;
  while (true) {
    ssize_t n = ::read(fd, buf.data(), buf.size());
    if (n < 0) Die("read failed");
    if (n == 0) break;
    sum += buf[0] + buf[static_cast<size_t>(n) - 1];
  }
  ::close(fd);
  return sum;
}

int WriteSample(const fs::path& db_dir) {
  Manifest manifest;
  manifest.tool_version = "format_bench";
  manifest.rolls = 48;
  manifest.metadata = {{"generator", "format_bench --write-sample (synthetic views)"}};
  for (uint32_t unit = 0; unit < 3; ++unit) {
    char name[32];
    std::snprintf(name, sizeof(name), "shard-%05u.hdb", unit);
    ShardWriter writer;
    ShardWriterOptions options;
    options.metadata_json = testing::SyntheticMetadata();
    Check(writer.Open(db_dir / name, options));
    for (uint32_t k = 0; k < 50; ++k) {
      const uint32_t id = unit * 50 + k;
      Check(writer.AddView(testing::SyntheticLabel(id), testing::SyntheticPoints(id, 80 + k)));
    }
    auto summary = writer.Finish();
    if (!summary.ok()) Die(summary.status().ToString());
    manifest.AddShard(*summary);
  }
  Check(WriteManifest(db_dir, manifest));
  std::printf("wrote %s (3 shards, %llu views)\n",
              db_dir.string().c_str(),
              static_cast<unsigned long long>(manifest.num_views));
  return 0;
}

struct Row {
  const char* name;
  std::vector<Time> times;
  double Wall() const {
    std::vector<double> v;
    for (const Time& t : times) v.push_back(t.wall);
    return Median(v);
  }
  double Cpu() const {
    std::vector<double> v;
    for (const Time& t : times) v.push_back(t.cpu);
    return Median(v);
  }
};

}  // namespace
}  // namespace handdb

int main(int argc, char** argv) {
  using namespace handdb;
  uint32_t num_views = 100000;
  size_t points_per_view = 600;
  int reps = 3;
  fs::path dir = fs::temp_directory_path();
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) Die("missing value after " + a);
      return argv[++i];
    };
    if (a == "--views") {
      num_views = static_cast<uint32_t>(std::stoul(next()));
    } else if (a == "--points") {
      points_per_view = std::stoul(next());
    } else if (a == "--reps") {
      reps = std::max(1, std::stoi(next()));
    } else if (a == "--dir") {
      dir = next();
    } else if (a == "--write-sample") {
      return WriteSample(next());
    } else if (a == "--help" || a == "-h") {
      std::printf(
          "Usage: format_bench [--views N] [--points P] [--reps R] [--dir DIR]\n"
          "       format_bench --write-sample DB_DIR\n");
      return 0;
    } else {
      Die("unknown argument " + a);
    }
  }
  const fs::path path = dir / ("handdb_format_bench_" + std::to_string(::getpid()) + ".hdb");

  // Inputs prepared up front so the write timing measures the writer: a pool of labels and of
  // point sets of ~P points (P-50 .. P+50), cycled.
  constexpr uint32_t kPool = 257;
  std::vector<ViewLabel> labels;
  std::vector<std::vector<PointQ>> point_sets;
  uint64_t payload_points = 0;
  for (uint32_t k = 0; k < kPool; ++k) {
    labels.push_back(testing::SyntheticLabel(k));
    const size_t n = points_per_view - std::min<size_t>(points_per_view, 50) + (k * 37) % 101;
    point_sets.push_back(testing::SyntheticPoints(k, n));
  }
  for (uint32_t i = 0; i < num_views; ++i) payload_points += point_sets[i % kPool].size();
  // Raw payload of a view: the label fields (ids, 20 angles, direction, theta, phi, roll,
  // 21x3 keypoints, diameter, scale, centre) + its points.
  const double label_bytes = static_cast<double>(shard::kViewOffPointCount);
  const double payload =
      label_bytes * num_views + static_cast<double>(payload_points) * sizeof(PointQ);

  Row write{"write (incl. fsync)", {}};
  Row raw{"raw read() of the file", {}};
  Row scan{"sequential scan (open + ScanViews, every point)", {}};
  Row scan_verify{"scan + checksums in one pass", {}};
  Row verify{"open + VerifyChecksums", {}};
  Row validate{"full validation (ValidateShardFile)", {}};
  uint64_t file_size = 0;
  volatile uint64_t sink = 0;
  for (int rep = 0; rep < reps; ++rep) {
    write.times.push_back(Seconds([&] {
      ShardWriter writer;
      ShardWriterOptions options;
      options.metadata_json = testing::SyntheticMetadata();
      Check(writer.Open(path, options));
      for (uint32_t i = 0; i < num_views; ++i) {
        ViewLabel l = labels[i % kPool];
        l.render_id = i;
        Check(writer.AddView(l, point_sets[i % kPool]));
      }
      auto summary = writer.Finish();
      if (!summary.ok()) Die(summary.status().ToString());
      file_size = summary->file_size;
    }));
    sink = sink + RawRead(path);  // warm the page cache
    raw.times.push_back(Seconds([&] { sink = sink + RawRead(path); }));
    scan.times.push_back(Seconds([&] {
      auto reader = ShardReader::Open(path);
      if (!reader.ok()) Die(reader.status().ToString());
      int64_t acc = 0;
      Check(reader->ScanViews([&](size_t, const ViewLabel& l, std::span<const PointQ> pts) {
        acc += TouchPoints(pts) + static_cast<int64_t>(l.joint_angles[0] * 1000);
        return Status::Ok();
      }));
      sink = sink + static_cast<uint64_t>(acc);
    }));
    scan_verify.times.push_back(Seconds([&] {
      auto reader = ShardReader::Open(path);
      if (!reader.ok()) Die(reader.status().ToString());
      int64_t acc = 0;
      Check(reader->ScanViews(
          [&](size_t, const ViewLabel&, std::span<const PointQ> pts) {
            acc += TouchPoints(pts);
            return Status::Ok();
          },
          {.verify_checksums = true}));
      sink = sink + static_cast<uint64_t>(acc);
    }));
    verify.times.push_back(Seconds([&] {
      auto reader = ShardReader::Open(path);
      if (!reader.ok()) Die(reader.status().ToString());
      Check(reader->VerifyChecksums());
    }));
    validate.times.push_back(Seconds([&] {
      ValidationReport r = ValidateShardFile(path);
      if (!r.ok()) Die("validation failed: " + r.problems.front().message);
    }));
  }
  std::error_code ec;
  fs::remove(path, ec);

  const double mb = static_cast<double>(file_size) / 1e6;
  std::printf("format_bench: %u views, %.1f points/view, %d repetitions (medians), file %s\n",
              num_views,
              static_cast<double>(payload_points) / num_views,
              reps,
              path.string().c_str());
  std::printf(
      "  file size %.1f MB, %.1f bytes/view; raw payload %.1f bytes/view "
      "(label %.0f + points); ratio %.4f (target <= 1.2)\n",
      mb,
      static_cast<double>(file_size) / num_views,
      payload / num_views,
      label_bytes,
      static_cast<double>(file_size) / payload);
  std::printf("  %-48s %9s %9s %11s %8s %8s %7s\n",
              "",
              "wall s",
              "cpu s",
              "views/s(cpu)",
              "MB/s",
              "MB/s",
              "vs raw");
  std::printf("  %-48s %9s %9s %11s %8s %8s %7s\n", "", "", "", "", "(wall)", "(cpu)", "(cpu)");
  const double raw_rate = mb / raw.Cpu();
  for (const Row* row : {&write, &raw, &scan, &scan_verify, &verify, &validate}) {
    std::printf("  %-48s %9.4f %9.4f %11.0f %8.0f %8.0f %6.0f%%\n",
                row->name,
                row->Wall(),
                row->Cpu(),
                num_views / row->Cpu(),
                mb / row->Wall(),
                mb / row->Cpu(),
                100.0 * (mb / row->Cpu()) / raw_rate);
  }
  const double scan_ratio = (mb / scan.Cpu()) / raw_rate;
  const double scan_ratio_wall = (mb / scan.Wall()) / (mb / raw.Wall());
  std::printf("  scan / raw read = %.2f by cpu time, %.2f by wall time (target >= 0.50): %s\n",
              scan_ratio,
              scan_ratio_wall,
              scan_ratio >= 0.5 ? "met" : "NOT met");
  return 0;
}
