// Every `handdb` subcommand: int RunX(int argc, char** argv), argv[0] is the subcommand name.
// Exit codes: 0 success, 1 user error (one clear line on stderr), 2 bad usage.
#pragma once

#include <filesystem>

#include "base/status.h"

namespace handdb {
struct DatabaseIndexSummary;  // query/index/database_index.h
}  // namespace handdb

namespace handdb::cli {

constexpr int kExitOk = 0;
constexpr int kExitError = 1;
constexpr int kExitUsage = 2;

int RunVersion(int argc, char** argv);
int RunPlan(int argc, char** argv);      // cli/generate_commands.cc
int RunRender(int argc, char** argv);    // cli/generate_commands.cc
int RunConvert(int argc, char** argv);   // cli/convert_commands.cc
int RunGenerate(int argc, char** argv);  // cli/convert_commands.cc
int RunShow(int argc, char** argv);      // cli/convert_commands.cc
int RunUnit(int argc, char** argv);      // cli/slurm_commands.cc
int RunInfo(int argc, char** argv);      // cli/format_commands.cc
int RunValidate(int argc, char** argv);  // cli/format_commands.cc
int RunTestset(int argc, char** argv);   // cli/evaluate_commands.cc
int RunEvaluate(int argc, char** argv);  // cli/evaluate_commands.cc
int RunQuery(int argc, char** argv);     // cli/query_commands.cc
int RunIndex(int argc, char** argv);     // cli/index_commands.cc
int RunTrack(int argc, char** argv);     // cli/track_commands.cc

// The one-line summary of an index written by WriteDatabaseIndex (query/index/database_index.h),
// led by `cmd`, on stdout.
void PrintIndexSummary(const char* cmd,
                       const std::filesystem::path& db_dir,
                       const DatabaseIndexSummary& summary);

}  // namespace handdb::cli
