// The command line of the benchmarks, parsed with CLI11 as `handdb` parses its own: each bench
// binds its flags to the fields of its Args struct (so a default exists once), and comma lists
// (--candidates 2000,8000) are vectors split at ','. Header-only (benchmarks are single files).
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace handdb::bench {

// Adds a comma-separated list option: "2000,8000" -> {2000, 8000}; the field's value is the
// default.
template <typename T>
CLI::Option* AddList(CLI::App& app,
                     const std::string& name,
                     std::vector<T>& values,
                     const std::string& help) {
  return app.add_option(name, values, help)->delimiter(',')->capture_default_str();
}

// The flags of the query sets (bench/query_sets.h) and the search threads, bound to the fields of
// those names of a bench's Args.
template <typename Args>
void AddQuerySetFlags(CLI::App& app, Args& args) {
  app.add_option("--db", args.db, "database directory");
  app.add_option("--photos", args.photos, "real photos, searched recursively")
      ->capture_default_str();
  app.add_option("--testset", args.testset, "test set made by `handdb testset`");
  app.add_option("--set-queries", args.set_queries, "queries per set, spread over it (0: all)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--threads", args.threads, "search threads")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
}

// Parses argv into the bound fields: -1 when the bench should run, else its exit code (0 after
// --help, 2 with one line and the usage on stderr after bad usage).
inline int ParseBenchArgs(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  }
  return -1;
}

}  // namespace handdb::bench
