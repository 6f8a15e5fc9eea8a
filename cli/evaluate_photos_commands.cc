// `handdb evaluate DB --photos DIR` (issue 16): shape accuracy of the search on real photographs
// sorted into one folder per expected shape, and 2D keypoint error on annotated ones
// (evaluate/photos.h, docs/evaluation.md).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/evaluate_cli.h"
#include "evaluate/photo_keypoints.h"
#include "evaluate/photos.h"
#include "query/input/image_edges.h"
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

// The report names the database and the photo directory as typed, like the test-set report, and
// records how pictures became queries.
void DescribeAsTyped(const std::string& db, const PhotoEvaluateFlags& flags, PhotoReport* report) {
  report->database = db;
  report->photos_dir = flags.dir;
  report->keypoints_file = flags.keypoints;
  report->query_options = flags.picture.ToJson();
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
  PhotoInputFlags::Which which;
  which.input = with_input;
  which.mask = false;
  picture.Add(app, which);
  for (const char* name :
       {"--roi", "--skin", "--canny", "--contour-clearance", "--edges-outside"}) {
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
  options.num_threads = threads;
  options.progress = !quiet;
  return options.Check();
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
  opened.query_fn = [options = picture.edges](const PhotoItem& item) {
    return LoadQueryEdges(item.path, options);
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
                           "--roi",
                           "--skin",
                           "--canny",
                           "--contour-clearance",
                           "--edges-outside"}) {
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

}  // namespace handdb::cli
