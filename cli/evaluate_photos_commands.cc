// `handdb evaluate DB --photos DIR` (issue 16): shape accuracy of the search on real photographs
// sorted into one folder per expected shape (evaluate/photos.h, docs/evaluation.md).
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
#include "evaluate/photos.h"
#include "query/input/image_edges.h"
#include "query/searcher.h"

namespace handdb::cli {

void AddPhotoEvaluateFlags(CLI::App& app, PhotoEvaluateRequest* request) {
  const char* group = "Real photos (instead of TESTSET)";
  app.add_option("--photos",
                 request->dir,
                 "score shape accuracy on photos in DIR/<shape name>/*.jpg|png (folders named "
                 "after the database's shapes)")
      ->group(group);
  app.add_option("--out",
                 request->out_dir,
                 "--photos: write confusion.png, successes.png and failures.png here")
      ->group(group);
  app.add_flag("--skip-unknown",
               request->skip_unknown,
               "--photos: skip folders that are not shapes of the database (default: an error)")
      ->group(group);
}

bool CheckPhotoEvaluateUsage(const CLI::App& app, const std::string& testset, bool slurm) {
  if (!testset.empty()) {
    std::fprintf(stderr, "handdb evaluate: give either a TESTSET or --photos DIR, not both\n");
    return false;
  }
  if (slurm) {
    std::fprintf(stderr, "handdb evaluate: --photos runs locally only (no --slurm)\n");
    return false;
  }
  for (const char* name : {"--input",
                           "--d",
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

int RunEvaluatePhotos(const PhotoEvaluateRequest& request) {
  if (request.threads == 0 || request.threads < -1) {
    std::fprintf(stderr, "handdb evaluate: --threads must be -1 or >= 1\n");
    return kExitUsage;
  }
  auto searcher = Searcher::Open(request.db);
  if (!searcher.ok()) return Fail("evaluate", searcher.status());
  const Database& db = (*searcher)->database();
  if (db.num_views() == 0) {
    return Fail("evaluate",
                Status(StatusCode::kNotFound, request.db + ": the database has no views"));
  }
  std::set<std::string> names;
  for (view_id_t v = 0; v < db.num_views(); ++v) {
    names.insert(std::string(db.shape_name(db.label(v).shape_id)));
  }
  names.erase("");
  const std::vector<std::string> shape_names(names.begin(), names.end());
  auto photos = ListPhotoFolders(request.dir, shape_names, request.skip_unknown);
  if (!photos.ok()) return Fail("evaluate", photos.status());

  // Each file is read as `handdb query` reads it (auto: photo, edge image or label EXR), so a
  // folder of edge images or label renders is scored like one of photos.
  ImageEdgeOptions image_options;
  image_options.kind = QueryInputKind::kAuto;
  const PhotoPointsFn points_fn =
      [image_options](const PhotoItem& item) -> Result<std::vector<Point2f>> {
    auto edges = LoadQueryEdges(item.path, image_options);
    if (!edges.ok()) return edges.status();
    return edges->points_px();
  };
  PhotoEvaluationOptions options;
  options.num_threads = request.threads;
  options.progress = !request.quiet;
  auto report = EvaluatePhotos(**searcher, *photos, points_fn, options);
  if (!report.ok()) return Fail("evaluate", report.status());
  report->database = request.db;  // as typed, like the test-set report
  report->photos_dir = request.dir;
  if (!request.quiet) std::printf("%s", PhotoReportToText(*report).c_str());
  if (!request.json_out.empty()) {
    const nlohmann::json doc = PhotoReportToJson(*report);
    Status s = ValidateJson(doc, "photo_evaluation.schema.json", request.json_out);
    if (s.ok()) s = WriteJsonFileAtomic(request.json_out, doc);
    if (!s.ok()) return Fail("evaluate", s);
  }
  if (!request.out_dir.empty()) {
    Status s = WritePhotoReportImages(*report, **searcher, *photos, request.out_dir);
    if (!s.ok()) return Fail("evaluate", s);
  }
  return kExitOk;
}

}  // namespace handdb::cli
