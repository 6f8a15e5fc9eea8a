// One `handdb` binary dispatching subcommands from a table (after COLMAP).
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <exception>
#include <ext/stdio_sync_filebuf.h>
#include <iostream>
#include <string>
#include <vector>

#include "cli/commands.h"
#include "handdb_version.h"

namespace handdb::cli {
namespace {

struct Command {
  const char* name;
  int (*run)(int, char**);
  const char* summary;
};

// Keep in the order of the pipeline.
const std::vector<Command>& Commands() {
  static const std::vector<Command> kCommands = {
      {"version", RunVersion, "print the handdb version"},
      {"plan",
       RunPlan,
       "turn a generation config into a render plan (shapes x view directions, units)"},
      {"render", RunRender, "render a plan's units with parallel Blender workers (resumable)"},
      {"convert",
       RunConvert,
       "convert a render dir into a database: shards + manifest (resumable)"},
      {"generate",
       RunGenerate,
       "config -> plan -> render -> convert -> validate, one command (resumable)"},
      {"unit", RunUnit, "one unit's render/convert, finalize, status: the Slurm array tasks' work"},
      {"show", RunShow, "draw a stored view's edges (any roll, optional keypoints) as a PNG"},
      {"info", RunInfo, "print a shard's header, sections and metadata, or a database summary"},
      {"validate", RunValidate, "check shards or databases completely (exit 1 on any problem)"},
      {"index",
       RunIndex,
       "build a database's search index for indexed search (filter, then exact refine)"},
      {"query",
       RunQuery,
       "top-k database views for a photo, edge image or label EXR (exact chamfer)"},
      {"track",
       RunTrack,
       "hand poses through a video or a folder of frames (local search, smoothing over time)"},
      {"testset",
       RunTestset,
       "plan and render a held-out test set with ground truth (labels + photos)"},
      {"evaluate",
       RunEvaluate,
       "score a database on a test set: Table 1, success@(d,n), keypoint error, q/s"},
  };
  return kCommands;
}

void PrintHelp(std::FILE* out) {
  std::fprintf(out,
               "handdb %s - databases of synthetic hand views for 3D hand pose estimation by "
               "retrieval\n\nUsage: handdb <command> [options]   (handdb <command> --help for "
               "details)\n\nCommands:\n",
               HANDDB_VERSION);
  for (const auto& c : Commands()) std::fprintf(out, "  %-10s %s\n", c.name, c.summary);
  std::fprintf(out, "  %-10s %s\n", "help", "show this help");
}

// The errno of the first write to fd 1 that failed. errno itself is no witness by the time the
// command returns: a buffer flushed mid-command failed long before, and later calls (isatty's
// ENOTTY, an open's ENOENT) overwrote it.
int g_stdout_write_errno = 0;

ssize_t WriteToFdOne(void* /*cookie*/, const char* data, size_t size) {
  size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(STDOUT_FILENO, data + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      if (g_stdout_write_errno == 0) g_stdout_write_errno = n < 0 ? errno : EIO;
      return static_cast<ssize_t>(done);  // short: the stream records the error
    }
    done += static_cast<size_t>(n);
  }
  return static_cast<ssize_t>(size);
}

// Routes printf and std::cout through one stream over fd 1 whose writes go through
// WriteToFdOne, buffered as glibc buffers stdout (by line on a terminal, in blocks otherwise).
void RecordStdoutWriteErrors() {
  static const cookie_io_functions_t kIo = {nullptr, WriteToFdOne, nullptr, nullptr};
  FILE* out = ::fopencookie(nullptr, "w", kIo);
  if (out == nullptr) return;  // keep the plain stdout; reasons may then be less precise
  std::setvbuf(out, nullptr, ::isatty(STDOUT_FILENO) ? _IOLBF : _IOFBF, BUFSIZ);
  std::fflush(stdout);
  stdout = out;
  // Never freed: std::cout is flushed at exit, after function-local statics are destroyed.
  std::cout.rdbuf(new __gnu_cxx::stdio_sync_filebuf<char>(out));
}

// Output that never reached its file is a failure (a full disk, /dev/full, a closed pipe): flush
// stdout once the command is done and turn a write error into exit 1 with one line naming the
// failed write's reason, so `handdb info DB --json > out.json` never exits 0 over an empty file.
int CheckStdout(const char* command, int code) {
  std::cout.flush();
  errno = 0;
  const bool flush_failed = std::fflush(stdout) != 0;
  const int flush_errno = errno;
  if (!flush_failed && !std::ferror(stdout) && std::cout.good()) return code;
  const int reason = g_stdout_write_errno != 0 ? g_stdout_write_errno : flush_errno;
  const char* why = reason != 0 ? std::strerror(reason) : "write error";
  std::fprintf(stderr, "handdb %s: cannot write to stdout: %s\n", command, why);
  return code == kExitOk ? kExitError : code;
}

}  // namespace

int RunVersion(int argc, char** argv) {
  if (argc > 1 && (std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0)) {
    std::printf("Usage: handdb version\nPrints the handdb version.\n");
    return kExitOk;
  }
  std::printf("handdb %s\n", HANDDB_VERSION);
  return kExitOk;
}

}  // namespace handdb::cli

int main(int argc, char** argv) {
  using namespace handdb::cli;
  RecordStdoutWriteErrors();
  if (argc < 2) {
    PrintHelp(stderr);
    return kExitUsage;
  }
  const std::string name = argv[1];
  if (name == "help" || name == "--help" || name == "-h") {
    PrintHelp(stdout);
    return CheckStdout("help", kExitOk);
  }
  if (name == "--version") return CheckStdout("version", RunVersion(1, argv + 1));
  for (const auto& c : Commands()) {
    if (name == c.name) {
      try {
        return CheckStdout(c.name, c.run(argc - 1, argv + 1));
      } catch (const std::exception& e) {
        // A broken internal invariant: report it, never crash silently.
        std::fprintf(stderr, "handdb %s: internal error: %s\n", c.name, e.what());
        return kExitError;
      }
    }
  }
  std::fprintf(stderr, "handdb: unknown command '%s' (see 'handdb help')\n", name.c_str());
  return kExitUsage;
}
