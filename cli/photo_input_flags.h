// The flags that say how a picture becomes a query and which hand it shows, bound once and shared
// by `handdb query` and `handdb evaluate --photos` (and the Slurm tasks of the latter), so each
// flag has one spelling, one default and one check (bind a flag to the field).
#pragma once

#include <CLI/CLI.hpp>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "photo/image_edges.h"
#include "pose/landmark_rank.h"
#include "pose/picture_search.h"
#include "query/database.h"
#include "query/searcher.h"

namespace handdb::cli {

// --input, --mask, --roi, --skin, --canny, --contour-clearance, --edges-outside,
// --work-diameter, --no-wrist-cut, bound to options.picture.edges; --landmarks, the model
// Finish loads once into options.picture.landmarker; --landmark-weight, bound to
// options.landmark_rank (pose/landmark_rank.h). A command binds its search flags to
// options.search.
struct PhotoInputFlags {
  std::string input = std::string(QueryInputKindName(QueryInputKind::kAuto));
  std::string mask, roi, skin, canny;
  // auto: the installed model (HandLandmarker::DefaultModelPath), or D_c alone with a warning
  // when it is not installed; off; or a model file.
  std::string landmarks = "auto";
  PictureSearchOptions options;

  // Which flags a command takes: --input (the kind of picture) only where no other --input
  // exists, --mask only where there is one picture (a mask belongs to one photo).
  struct Which {
    bool input = true;
    bool mask = true;
  };
  void Add(CLI::App& app, Which which);
  // Completes `options.picture` from the text flags and opens the landmark model; false (one line
  // "handdb <cmd>: ..." on stderr) on bad usage or a model that cannot be loaded.
  bool Finish(const std::string& cmd);
  // Finish in two steps, so a command can load the model while it opens its database: the text
  // flags (false: bad usage, exit 2), then the landmark model (false: failure_exit_code). Neither
  // prints anything to stdout; OpenLandmarker writes only `options.picture.landmarker` and
  // `options.landmark_rank`.
  bool FinishFlags(const std::string& cmd);
  bool OpenLandmarker(const std::string& cmd);
  // After Finish failed: the exit code it means. A model file that cannot be loaded is a user
  // error (1), like any other file; the rest is bad usage (2).
  int failure_exit_code = 2;
  // Label EXRs become queries exactly like the database's views: the edge options its manifest
  // records (from the manifest `db` was opened with; a convert may have replaced the file since).
  Status UseDatabaseConversion(const Database& db, const std::filesystem::path& db_dir);
  // The flags that reproduce `options.picture` and the landmark weight in another process (a
  // Slurm task), without --mask.
  std::vector<std::string> Args() const;
  // The resolved options that change a query (not the mask), for fingerprints and reports.
  nlohmann::json ToJson() const;
};

// The landmark model `spec` names: "off" -> null; "auto" -> the installed model
// (HandLandmarker::DefaultModelPath), or null with a one-line warning on stderr when it is not
// installed; else the model file. False (one line "handdb <cmd>: ..." on stderr) when a model
// cannot be loaded.
bool ResolveLandmarker(const std::string& spec,
                       const std::string& cmd,
                       std::shared_ptr<const HandLandmarker>* out);

// --hand right|left|either. The default is `handdb query`'s (either: the query and its mirror
// image are both searched); the library's SearchOptions keeps kRight.
struct HandFlag {
  std::string name = std::string(HandName(Hand::kEither));
  // `what` names the picture in the help text ("IMAGE", "each photo").
  void Add(CLI::App& app, const std::string& what);
  Hand Get() const { return *ParseHand(name); }
};

}  // namespace handdb::cli
