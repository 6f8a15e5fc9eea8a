// What `handdb evaluate` shares with the Slurm array tasks and the merge job of
// `handdb evaluate --slurm` (`handdb unit evaluate|evaluate-merge`,
// cli/evaluate_slurm_commands.cc): the options that define an evaluation, the query-input function,
// the database/test-set checks, and the same for real photos (`handdb evaluate DB --photos DIR`,
// `handdb unit evaluate-photos|evaluate-photos-merge`, cli/evaluate_photos_commands.cc). Sharing
// them is what makes a Slurm evaluation score exactly like a local one.
#pragma once

#include <CLI/CLI.hpp>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli/photo_input_flags.h"
#include "cli/slurm_cli.h"
#include "evaluate/evaluate.h"
#include "evaluate/photos.h"
#include "evaluate/sequence.h"
#include "query/database.h"
#include "query/searcher.h"

namespace handdb::cli {

// The evaluation options of `handdb evaluate` (correctness, search depth, test-view selection,
// input, threads), parsed once and passed on to Slurm tasks verbatim (Args()). --input also
// takes the kinds of picture of --photos (auto, edges, labels; cli/photo_input_flags.h), which
// Finish refuses for a test set.
struct EvaluateFlags {
  std::string input = "clean";
  std::string distance = "rms";
  std::string roll_compare = "aligned";
  std::string search = "auto";  // IndexUse, as `handdb query --search`
  std::string fit = "auto";     // as `handdb query --fit`: photo queries only
  EvaluationOptions options;
  // --input photo: the installed landmark model (ResolveLandmarker("auto")), as `handdb query`
  // uses by default; a test set's photos take the photo path's defaults.
  std::shared_ptr<const HandLandmarker> landmarker;
  void Add(CLI::App& app);
  // Completes `options` after parsing; false (message printed) on bad usage, or when the landmark
  // model cannot be loaded (then failure_exit_code is 1, not the usage error's 2).
  bool Finish(const std::string& cmd, bool quiet);
  int failure_exit_code = 2;
  QueryInput query_input() const {
    return input == "clean" ? QueryInput::kClean : QueryInput::kPhoto;
  }
  // The flags that reproduce input and every scoring option exactly (not --threads, --quiet).
  std::vector<std::string> Args() const;
  // How the searcher opens DB: the search threads, and the index as --search says.
  SearcherOptions searcher_options() const;
  // --fit: loads DB_DIR's rig into options.fit_rig for photo queries (auto: when it has one).
  // False (message printed) when --fit on finds none.
  bool LoadFit(const std::filesystem::path& db_dir, const std::string& cmd);
};

// Test view -> query edge points: the clean label render through the database's own conversion
// (the edge options its manifest records), or the photo through the real-image path.
// `db` is DB_DIR opened: its manifest's recorded edge options convert clean (label) queries.
// A photo's landmarks come from `landmarker` (null: none).
Result<QueryPointsFn> MakeQueryPointsFn(QueryInput input,
                                        const std::filesystem::path& db_dir,
                                        const Database& db,
                                        std::shared_ptr<const HandLandmarker> landmarker);

// Warns on stderr when the database's manifest records the test set's seed or another hand model.
void WarnIfTestSetMatchesDatabase(const std::filesystem::path& db_dir, const TestSet& testset);

struct EvaluateSlurmRequest {
  std::string db;       // as typed: jobs run in the submission directory, so the report's paths
  std::string testset;  // are the ones a local run with the same arguments prints
  std::string json_out;
  std::string plots_dir;
  EvaluateFlags flags;
  uint32_t tasks = 0;          // 0: one task per 16 selected test views, at most 1000
  std::filesystem::path work;  // empty: TESTSET_DIR/slurm-evaluations/<fingerprint>
  bool quiet = false;
};
// ---- Sequence test sets: `handdb evaluate DB SEQUENCE-TESTSET`
// (cli/evaluate_sequence_commands.cc) The scoring options of sequences (recovery window and error,
// how many sequences).
struct SequenceEvaluateFlags {
  SequenceScoreOptions options;
  std::string predictor = "tracker";  // "tracker" (handdb track's defaults) or "alone"
  std::string smooth = "online";      // the tracker's smoothing
  void Add(CLI::App& app);
};

// Scores the tracker (or the predictor that answers each frame alone) on the sequence test set
// request.testset;
// `input_given`: --input was on the command line (only photo applies). Returns the exit code.
int RunEvaluateSequences(EvaluateSlurmRequest request,
                         const SequenceEvaluateFlags& sequence_flags,
                         bool input_given);

// `handdb evaluate DB TESTSET --slurm ...`: submits (or with --dry-run only writes) an array of
// tasks for the parts that are missing plus the merge job; with --wait, waits and prints the
// report as a local run does. Returns the exit code.
int RunEvaluateOnSlurm(const EvaluateSlurmRequest& request, const SlurmFlags& flags);

// What `handdb evaluate --slurm` submits, for a test set and for photos alike: the files and the
// task and merge command lines, how many items (test views, photos) over how many tasks, and
// which parts are complete.
struct SlurmEvaluation {
  SlurmEvaluateLayout layout;
  std::string items_noun;  // "test views", "photos"
  uint32_t num_items = 0;
  uint32_t tasks = 0;
  std::string merge_command;  // "unit evaluate-merge": its one-line errors in the merge log
  // Parts 0..tasks-1: complete or not; an error for a part of another evaluation (CompleteParts).
  std::function<Result<std::vector<bool>>()> complete_parts;
};
// Submits the tasks whose part is missing plus the merge job (--dry-run: writes the scripts and
// prints the sbatch lines); refuses while jobs of an earlier submission run; with --wait, waits,
// names each failed task with its log, and prints the merged report. Returns the exit code.
int SubmitSlurmEvaluation(const SlurmEvaluation& evaluation, const SlurmFlags& flags, bool quiet);
// Parts 0..num_tasks-1 from `read_part` (the part's ReadPart status): complete (ok) or work for its
// task (any error but kInvalidArgument); a part of another evaluation (kInvalidArgument) is the
// error returned.
Result<std::vector<bool>> CompleteParts(uint32_t num_tasks,
                                        const std::function<Status(uint32_t)>& read_part);
// The layout of an evaluation in `work` (made absolute) whose jobs run `task_args` and
// `merge_args` (the words after `handdb`) with this executable, from the current directory.
Result<SlurmEvaluateLayout> MakeSlurmEvaluateLayout(const std::filesystem::path& work,
                                                    std::vector<std::string> task_args,
                                                    std::vector<std::string> merge_args);
// The default --tasks: one per 16 items, at most 1000.
uint32_t DefaultEvaluationTasks(uint32_t items);
// Seconds since the Unix epoch: a part's started_at and finished_at, whose span over all parts is
// a Slurm run's wall time.
double UnixNow();

// `handdb unit evaluate` and `handdb unit evaluate-merge`, added to `handdb unit`'s app.
class UnitEvaluateCommands {
 public:
  explicit UnitEvaluateCommands(CLI::App& unit_app);
  bool parsed() const;
  int Run();

 private:
  CLI::App* task_cmd_ = nullptr;
  CLI::App* merge_cmd_ = nullptr;
  std::string db_;
  std::string testset_;
  std::filesystem::path work_;
  uint32_t tasks_ = 1;
  uint32_t task_ = 0;
  std::string json_out_;
  std::string plots_dir_;
  bool quiet_ = false;
  EvaluateFlags flags_;
};

// ---- Real photos: `handdb evaluate DB --photos DIR` (cli/evaluate_photos_commands.cc) ----------

// The options that define a photo evaluation, parsed once and passed on to Slurm tasks verbatim
// (Args()): the photo directory and its listing, the annotations, the hand, how a picture becomes
// a query.
struct PhotoEvaluateFlags {
  std::string dir;  // --photos
  bool skip_unknown = false;
  std::string keypoints;  // --keypoints FILE
  HandFlag hand;
  std::string rank = "shapes";  // --rank shapes|views
  PhotoInputFlags picture;
  PhotoEvaluationOptions options;  // completed by Finish

  // --photos, --skip-unknown, --keypoints, --hand and the photo-path flags (no --mask: a mask is
  // one photo's; --input only when `with_input`: `handdb evaluate` has one of its own).
  void Add(CLI::App& app, bool with_input);
  // Completes `options` and the picture options; false (one line printed) on bad usage.
  bool Finish(const std::string& cmd, int threads, bool quiet);
  // The flags that reproduce this evaluation's photos and scores (not --threads, --quiet).
  std::vector<std::string> Args() const;
  // The options that change outcomes (evaluate/parts.h, the Slurm fingerprint).
  nlohmann::json ScoringJson() const;
};

// A photo evaluation opened: the searcher, the listed photos with their annotations, and how each
// photo becomes a query (read as `handdb query` reads a picture, label EXRs with the database's
// recorded edge options).
struct OpenedPhotoEvaluation {
  std::unique_ptr<Searcher> searcher;
  PhotoSet photos;
  PhotoQueryFn query_fn;
};
// Errors name the file: the database, the photo directory, the --keypoints file.
Result<OpenedPhotoEvaluation> OpenPhotoEvaluation(const std::string& db,
                                                  const PhotoEvaluateFlags& flags);

struct PhotoEvaluateRequest {
  std::string db;  // as typed (see EvaluateSlurmRequest)
  PhotoEvaluateFlags flags;
  std::string json_out;
  std::string out_dir;  // --out: confusion.png, successes.png, failures.png
  bool quiet = false;
  uint32_t tasks = 0;          // --slurm: 0 = one task per 16 photos, at most 1000
  std::filesystem::path work;  // --slurm: empty = ./slurm-evaluations/<fingerprint>
};
// --photos, --out and the photo flags of PhotoEvaluateFlags, added to `handdb evaluate`'s app.
void AddPhotoEvaluateFlags(CLI::App& app, PhotoEvaluateRequest* request);
// With --photos: false (message printed) when a TESTSET or a test-set-only flag comes with it.
bool CheckPhotoEvaluateUsage(const CLI::App& app, const std::string& testset);
// With a TESTSET: false (message printed) when a --photos-only flag comes with it.
bool CheckTestSetEvaluateUsage(const CLI::App& app);
// The local run (one process) and the Slurm split; return the exit code.
int RunEvaluatePhotos(const PhotoEvaluateRequest& request);
int RunEvaluatePhotosOnSlurm(const PhotoEvaluateRequest& request, const SlurmFlags& flags);

// `handdb unit evaluate-photos` and `handdb unit evaluate-photos-merge`, added to `handdb unit`'s
// app: the array tasks and the merge job of `handdb evaluate DB --photos DIR --slurm`.
class UnitEvaluatePhotosCommands {
 public:
  explicit UnitEvaluatePhotosCommands(CLI::App& unit_app);
  bool parsed() const;
  int Run();

 private:
  CLI::App* task_cmd_ = nullptr;
  CLI::App* merge_cmd_ = nullptr;
  std::string db_;
  std::filesystem::path work_;
  uint32_t tasks_ = 1;
  uint32_t task_ = 0;
  int threads_ = -1;
  std::string json_out_;
  std::string out_dir_;
  bool quiet_ = false;
  PhotoEvaluateFlags flags_;
};

}  // namespace handdb::cli
