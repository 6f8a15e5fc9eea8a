// Helpers every `handdb` subcommand shares: argument parsing with CLI11 and the one-line error.
#pragma once

#include <CLI/CLI.hpp>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "cli/commands.h"
#include "edges/edges.h"

namespace handdb::cli {

// Exit code when the user interrupted a run (128 + SIGINT, as shells report it).
constexpr int kExitInterrupted = 130;

// Parses argv; returns -1 to go on, else the exit code (--help: 0, bad usage: 2).
inline int ParseArgs(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help prints and succeeds; bad usage is one line naming the command, like every error.
    if (e.get_exit_code() == 0) return app.exit(e) == 0 ? kExitOk : kExitUsage;
    std::fprintf(stderr, "%s: %s\n", app.get_name().c_str(), e.what());
    return kExitUsage;
  }
  return -1;
}

// "handdb <cmd>: <message>" on stderr.
inline void PrintError(std::string_view cmd, const Status& status) {
  std::fprintf(stderr,
               "handdb %.*s: %s\n",
               static_cast<int>(cmd.size()),
               cmd.data(),
               status.message().c_str());
}

// PrintError; exit 1 (130 when the run was interrupted).
inline int Fail(std::string_view cmd, const Status& status) {
  PrintError(cmd, status);
  return status.code() == StatusCode::kCancelled ? kExitInterrupted : kExitError;
}

// --occlusion-edges and --depth-jump, spelled alike in every command that converts label renders.
class EdgeFlags {
 public:
  // `depth_jump_help` is the commands' own wording of --depth-jump.
  void Add(CLI::App& app, const char* depth_jump_help) {
    typed_.push_back(
        app.add_option("--occlusion-edges",
                       occlusion_,
                       "keep joint-pair borders across a depth jump as occlusion edges (on|off)")
            ->check(CLI::IsMember({"on", "off"}))
            ->capture_default_str());
    typed_.push_back(app.add_option("--depth-jump", edges_.depth_jump, depth_jump_help)
                         ->check(CLI::PositiveNumber)
                         ->capture_default_str());
  }
  EdgeOptions Get() const {
    EdgeOptions e = edges_;
    e.occlusion_edges = occlusion_ == "on";
    return e;
  }
  // The flags as typed (none that were left out), to pass on to a command that must convert the
  // same way: its defaults are these.
  std::vector<std::string> Typed() const {
    std::vector<std::string> words;
    for (const CLI::Option* o : typed_) {
      for (const std::string& value : o->results()) {
        words.push_back(o->get_name());
        words.push_back(value);
      }
    }
    return words;
  }

 private:
  EdgeOptions edges_;
  std::string occlusion_ = EdgeOptions{}.occlusion_edges ? "on" : "off";
  std::vector<const CLI::Option*> typed_;
};

}  // namespace handdb::cli
