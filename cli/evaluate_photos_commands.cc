// `handdb evaluate DB --photos DIR`: shape accuracy of the search on real photographs
// sorted into one folder per expected shape, and 2D keypoint error on annotated ones
// (evaluate/photos.h, docs/evaluation.md). Locally in one process, or with --slurm as a job array
// of `handdb unit evaluate-photos` tasks and a `handdb unit evaluate-photos-merge` job
// (docs/cluster.md): both score a photo with ScorePhotos and aggregate with FinishPhotoReport.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/thread_pool.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/evaluate_cli.h"
#include "evaluate/parts.h"
#include "evaluate/photo_keypoints.h"
#include "evaluate/photos.h"
#include "photo/image_edges.h"
#include "query/searcher.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

const char* kPhotoGroup = "Real photos (instead of TESTSET)";

// The report's outputs: --json (schema-checked, atomic) and --out images.
Status WritePhotoOutputs(const PhotoReport& report,
                         const OpenedPhotoEvaluation& opened,
                         const std::string& json_out,
                         const std::string& out_dir) {
  if (!json_out.empty()) {
    const json doc = PhotoReportToJson(report);
    HANDDB_RETURN_IF_ERROR(ValidateJson(doc, "photo_evaluation.schema.json", json_out));
    HANDDB_RETURN_IF_ERROR(WriteJsonFileAtomic(json_out, doc));
  }
  if (!out_dir.empty()) {
    HANDDB_RETURN_IF_ERROR(
        WritePhotoReportImages(report, *opened.searcher, opened.photos, out_dir, opened.query_fn));
  }
  return Status::Ok();
}

// The report names the database and the photo directory as typed (the jobs of a Slurm run get
// them verbatim, so both runs print the same paths) and records how pictures became queries.
void DescribeAsTyped(const std::string& db, const PhotoEvaluateFlags& flags, PhotoReport* report) {
  report->database = db;
  report->photos_dir = flags.dir;
  report->keypoints_file = flags.keypoints;
  report->query_options = flags.picture.ToJson();
}

// The parts of a photo evaluation in WORK (CompleteParts).
Result<std::vector<bool>> CompletePhotoParts(const fs::path& work,
                                             const EvaluationFingerprint& fp,
                                             const PhotoSet& photos,
                                             uint32_t num_tasks) {
  return CompleteParts(num_tasks, [&](uint32_t t) {
    return ReadPart(PartPath(work, t), ExpectedPart(fp, t, photos)).status();
  });
}

}  // namespace

void PhotoEvaluateFlags::Add(CLI::App& app, bool with_input) {
  app.add_option("--photos",
                 dir,
                 "score shape accuracy on photos in DIR/<shape name>/*.jpg|png (folders named "
                 "after the database's shapes)")
      ->group(kPhotoGroup);
  app.add_flag("--skip-unknown",
               skip_unknown,
               "--photos: skip folders that are not shapes of the database (default: an error)")
      ->group(kPhotoGroup);
  app.add_option("--keypoints",
                 keypoints,
                 "--photos: 2D keypoint annotations (schemas/photo_keypoints.schema.json); adds "
                 "the keypoint error of the top-1 match and the best of the top 10")
      ->group(kPhotoGroup);
  hand.Add(app, "each photo");
  app.get_option("--hand")->group(kPhotoGroup);
  app.add_option("--rank",
                 rank,
                 "--photos: shapes: top-k = the k nearest shapes (one match per shape, the usual "
                 "top-k accuracy); views: top-k = the shapes of the k nearest views")
      ->check(CLI::IsMember({"shapes", "views"}))
      ->capture_default_str()
      ->group(kPhotoGroup);
  PhotoInputFlags::Which which;
  which.input = with_input;
  which.mask = false;
  picture.Add(app, which);
  for (const char* name : {"--roi",
                           "--skin",
                           "--canny",
                           "--contour-clearance",
                           "--edges-outside",
                           "--landmarks",
                           "--landmark-weight"}) {
    app.get_option(name)->group(kPhotoGroup);
  }
  if (with_input) app.get_option("--input")->group(kPhotoGroup);
}

bool PhotoEvaluateFlags::Finish(const std::string& cmd, int threads, bool quiet) {
  if (threads == 0 || threads < -1) {
    std::fprintf(stderr, "handdb %s: --threads must be -1 or >= 1\n", cmd.c_str());
    return false;
  }
  if (!picture.Finish(cmd)) return false;
  options.hand = hand.Get();
  options.max_per_shape = rank == "shapes" ? 1 : 0;
  options.landmark_rank = picture.options.landmark_rank;
  options.num_threads = threads;
  options.progress = !quiet;
  return options.Check();
}

std::vector<std::string> PhotoEvaluateFlags::Args() const {
  std::vector<std::string> args = {"--photos", dir, "--hand", hand.name, "--rank", rank};
  if (skip_unknown) args.push_back("--skip-unknown");
  if (!keypoints.empty()) args.insert(args.end(), {"--keypoints", keypoints});
  const auto picture_args = picture.Args();
  args.insert(args.end(), picture_args.begin(), picture_args.end());
  return args;
}

json PhotoEvaluateFlags::ScoringJson() const {
  return PhotoScoringOptionsToJson(options, picture.ToJson());
}

Result<OpenedPhotoEvaluation> OpenPhotoEvaluation(const std::string& db,
                                                  const PhotoEvaluateFlags& flags) {
  OpenedPhotoEvaluation opened;
  auto searcher = Searcher::Open(db);
  if (!searcher.ok()) return searcher.status();
  opened.searcher = std::move(*searcher);
  const Database& database = opened.searcher->database();
  if (database.num_views() == 0) {
    return Status(StatusCode::kNotFound, db + ": the database has no views");
  }
  std::set<std::string> names;
  for (view_id_t v = 0; v < database.num_views(); ++v) {
    names.insert(std::string(database.shape_name(database.label(v).shape_id)));
  }
  names.erase("");
  const std::vector<std::string> shape_names(names.begin(), names.end());
  auto photos = ListPhotoFolders(flags.dir, shape_names, flags.skip_unknown);
  if (!photos.ok()) return photos.status();
  opened.photos = std::move(*photos);
  if (!flags.keypoints.empty()) {
    auto annotations = ReadPhotoKeypoints(flags.keypoints);
    if (!annotations.ok()) return annotations.status();
    HANDDB_RETURN_IF_ERROR(AttachPhotoKeypoints(*annotations, &opened.photos));
  }
  // Each file is read as `handdb query` reads it (auto: photo, edge image or label EXR), so a
  // folder of edge images or label renders is scored like one of photos.
  PhotoInputFlags picture = flags.picture;
  HANDDB_RETURN_IF_ERROR(picture.UseDatabaseConversion(database, db));
  opened.query_fn = [options = picture.options.picture](const PhotoItem& item) {
    return ReadPicture(item.path, options);
  };
  return opened;
}

void AddPhotoEvaluateFlags(CLI::App& app, PhotoEvaluateRequest* request) {
  request->flags.Add(app, /*with_input=*/false);
  app.add_option("--out",
                 request->out_dir,
                 "--photos: write confusion.png, successes.png and failures.png here")
      ->group(kPhotoGroup);
}

bool CheckPhotoEvaluateUsage(const CLI::App& app, const std::string& testset) {
  if (!testset.empty()) {
    std::fprintf(stderr, "handdb evaluate: give either a TESTSET or --photos DIR, not both\n");
    return false;
  }
  for (const char* name : {"--d",
                           "--distance",
                           "--max-direction",
                           "--max-roll",
                           "--roll-compare",
                           "--same-shape",
                           "--first-k",
                           "--max-rank",
                           "--stride",
                           "--limit",
                           "--plots"}) {
    if (app.get_option(name)->count() > 0) {
      std::fprintf(stderr,
                   "handdb evaluate: %s scores test sets; with --photos use --out for images\n",
                   name);
      return false;
    }
  }
  return true;
}

bool CheckTestSetEvaluateUsage(const CLI::App& app) {
  for (const char* name : {"--out",
                           "--skip-unknown",
                           "--keypoints",
                           "--hand",
                           "--rank",
                           "--roi",
                           "--skin",
                           "--canny",
                           "--contour-clearance",
                           "--edges-outside",
                           "--work-diameter",
                           "--no-wrist-cut",
                           "--landmarks",
                           "--landmark-weight"}) {
    if (app.get_option(name)->count() > 0) {
      std::fprintf(stderr,
                   "handdb evaluate: %s applies to --photos DIR; a test set uses --plots and its "
                   "own photos' defaults\n",
                   name);
      return false;
    }
  }
  return true;
}

int RunEvaluatePhotos(const PhotoEvaluateRequest& request) {
  auto opened = OpenPhotoEvaluation(request.db, request.flags);
  if (!opened.ok()) return Fail("evaluate", opened.status());
  auto report =
      EvaluatePhotos(*opened->searcher, opened->photos, opened->query_fn, request.flags.options);
  if (!report.ok()) return Fail("evaluate", report.status());
  DescribeAsTyped(request.db, request.flags, &*report);
  if (!request.quiet) std::printf("%s", PhotoReportToText(*report).c_str());
  const Status s = WritePhotoOutputs(*report, *opened, request.json_out, request.out_dir);
  if (!s.ok()) return Fail("evaluate", s);
  return kExitOk;
}

int RunEvaluatePhotosOnSlurm(const PhotoEvaluateRequest& request, const SlurmFlags& flags) {
  const char* cmd = "evaluate";
  // The login node lists the photos and reads the annotations as every task will, so a bad
  // directory or --keypoints file fails here, once.
  auto opened = OpenPhotoEvaluation(request.db, request.flags);
  if (!opened.ok()) return Fail(cmd, opened.status());
  const PhotoSet& photos = opened->photos;
  const uint32_t num_photos = static_cast<uint32_t>(photos.photos.size());
  const uint32_t tasks = request.tasks == 0 ? DefaultEvaluationTasks(num_photos) : request.tasks;
  if (tasks > num_photos) {
    std::fprintf(
        stderr, "handdb %s: --tasks %u: more tasks than the %u photos\n", cmd, tasks, num_photos);
    return kExitUsage;
  }
  auto fp =
      ComputePhotoEvaluationFingerprint(request.db, photos, request.flags.ScoringJson(), tasks);
  if (!fp.ok()) return Fail(cmd, fp.status());
  // Not inside DIR by default: its sub-folders are shape folders.
  auto work =
      Absolute(request.work.empty() ? fs::path("slurm-evaluations") / fp->value : request.work);
  if (!work.ok()) return Fail(cmd, work.status());
  std::vector<std::string> common = {
      request.db, "--tasks", std::to_string(tasks), "--work", work->string()};
  const auto photo_args = request.flags.Args();
  common.insert(common.end(), photo_args.begin(), photo_args.end());
  std::vector<std::string> task_args = {"unit", "evaluate-photos"};
  task_args.insert(task_args.end(), common.begin(), common.end());
  std::vector<std::string> merge_args = {"unit", "evaluate-photos-merge"};
  merge_args.insert(merge_args.end(), common.begin(), common.end());
  if (!request.json_out.empty()) merge_args.insert(merge_args.end(), {"--json", request.json_out});
  if (!request.out_dir.empty()) merge_args.insert(merge_args.end(), {"--out", request.out_dir});
  auto layout = MakeSlurmEvaluateLayout(*work, std::move(task_args), std::move(merge_args));
  if (!layout.ok()) return Fail(cmd, layout.status());

  SlurmEvaluation e;
  e.layout = std::move(*layout);
  e.items_noun = "photos";
  e.num_items = num_photos;
  e.tasks = tasks;
  e.merge_command = "unit evaluate-photos-merge";
  e.complete_parts = [work = e.layout.work_dir, fp = *fp, &photos, tasks] {
    return CompletePhotoParts(work, fp, photos, tasks);
  };
  return SubmitSlurmEvaluation(e, flags, request.quiet);
}

UnitEvaluatePhotosCommands::UnitEvaluatePhotosCommands(CLI::App& unit_app) {
  task_cmd_ = unit_app.add_subcommand(
      "evaluate-photos",
      "score one slice of a photo directory, as array task T of `handdb evaluate DB --photos DIR "
      "--slurm` does: the photos at positions k with k % TASKS == T (sorted by path), into "
      "WORK/parts/part-0000T.json (kept when already complete)");
  merge_cmd_ = unit_app.add_subcommand(
      "evaluate-photos-merge",
      "merge the parts of `handdb evaluate DB --photos DIR --slurm` into the report a local run "
      "writes: text on stdout and in WORK/report.txt, --json, --out");
  for (CLI::App* app : {task_cmd_, merge_cmd_}) {
    app->add_option("db", db_, "database directory")->required();
    app->add_option("--tasks", tasks_, "number of tasks the photos are split over")
        ->required()
        ->check(CLI::Range(1, 100000));
    app->add_option("--work", work_, "the evaluation's work directory (parts/ inside)")->required();
    flags_.Add(*app, /*with_input=*/true);
    app->get_option("--photos")->required();
    app->add_flag("-q,--quiet", quiet_, "no progress (merge: no text report on stdout)");
  }
  task_cmd_->add_option("--task", task_, "this task's number (0-based)")->required();
  task_cmd_->add_option(
      "--threads", threads_, "photos searched in parallel (default: $SLURM_CPUS_PER_TASK or 1)");
  merge_cmd_->add_option(
      "--json", json_out_, "write the full report (schemas/photo_evaluation.schema.json)");
  merge_cmd_->add_option(
      "--out", out_dir_, "write confusion.png, successes.png and failures.png here");
}

bool UnitEvaluatePhotosCommands::parsed() const {
  return task_cmd_->parsed() || merge_cmd_->parsed();
}

int UnitEvaluatePhotosCommands::Run() {
  const bool merge = merge_cmd_->parsed();
  const std::string cmd_name = merge ? "unit evaluate-photos-merge" : "unit evaluate-photos";
  const char* cmd = cmd_name.c_str();
  const int threads = merge ? 1 : (threads_ == -1 ? TaskThreads() : threads_);
  if (!flags_.Finish(cmd_name, threads, quiet_)) return flags_.picture.failure_exit_code;
  if (!merge && task_ >= tasks_) {
    std::fprintf(stderr, "handdb %s: --task %u: must be below --tasks %u\n", cmd, task_, tasks_);
    return kExitUsage;
  }
  auto opened = OpenPhotoEvaluation(db_, flags_);
  if (!opened.ok()) return Fail(cmd, opened.status());
  auto fp = ComputePhotoEvaluationFingerprint(db_, opened->photos, flags_.ScoringJson(), tasks_);
  if (!fp.ok()) return Fail(cmd, fp.status());

  if (merge) {
    PhotoReport report =
        StartPhotoReport(opened->searcher->database(), opened->photos, flags_.options);
    DescribeAsTyped(db_, flags_, &report);
    Status s = MergeParts(work_, *fp, opened->photos, &report);
    if (!s.ok()) return Fail(cmd, s);
    const std::string text = PhotoReportToText(report);
    s = WritePhotoOutputs(report, *opened, json_out_, out_dir_);
    if (!s.ok()) return Fail(cmd, s);
    // Last: its presence tells `handdb evaluate --slurm --wait` that the merge succeeded.
    SlurmEvaluateLayout layout;
    layout.work_dir = work_;
    s = WriteFileAtomic(layout.report_text(), text);
    if (!s.ok()) return Fail(cmd, s);
    if (!quiet_) std::printf("%s", text.c_str());
    return kExitOk;
  }

  const std::vector<uint32_t> slice = TaskSlice(opened->photos.photos.size(), task_, tasks_);
  const auto expect = ExpectedPart(*fp, task_, opened->photos);
  const fs::path path = PartPath(work_, task_);
  if (auto existing = ReadPart(path, expect); existing.ok()) {
    std::printf("task %u: %s already complete (%zu photos); kept\n",
                task_,
                path.c_str(),
                existing->rows.size());
    return kExitOk;
  }
  PhotoEvaluationPart part;
  part.fingerprint = *fp;
  part.task = task_;
  part.num_tasks = tasks_;
  part.threads = ResolveNumThreads(flags_.options.num_threads);
  part.started_at = UnixNow();
  auto outcomes =
      ScorePhotos(*opened->searcher, opened->photos, opened->query_fn, flags_.options, slice);
  if (!outcomes.ok()) return Fail(cmd, outcomes.status());
  part.rows = std::move(*outcomes);
  part.finished_at = UnixNow();
  Status s = WritePart(path, part);
  if (!s.ok()) return Fail(cmd, s);
  std::printf("task %u: %zu photos in %.1f s -> %s\n",
              task_,
              part.rows.size(),
              part.finished_at - part.started_at,
              path.c_str());
  return kExitOk;
}

}  // namespace handdb::cli
