// Helpers every `handdb` subcommand shares: argument parsing with CLI11 and the one-line error.
#pragma once

#include <CLI/CLI.hpp>
#include <cstdio>
#include <string_view>

#include "base/status.h"
#include "cli/commands.h"

namespace handdb::cli {

// Exit code when the user interrupted a run (128 + SIGINT, as shells report it).
constexpr int kExitInterrupted = 130;

// Parses argv; returns -1 to go on, else the exit code (--help: 0, bad usage: 2).
inline int ParseArgs(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kExitOk : kExitUsage;
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

}  // namespace handdb::cli
