// One entry from a picture to ranked matches: the picture's evidence (photo/image_edges.h: its
// edges and, for a photo, the hand landmarks), the exact search of its edges (query/searcher.h)
// and the re-ranking by the landmarks (pose/landmark_rank.h). `handdb query`, `handdb evaluate
// --photos` and Python's Database.search go through it, so a picture ranks the same everywhere.
#pragma once

#include <filesystem>
#include <memory>
#include <vector>

#include "base/status.h"
#include "generator/hand/database_rig.h"
#include "photo/image_edges.h"
#include "pose/fit_matches.h"
#include "pose/landmark_rank.h"
#include "query/searcher.h"

namespace handdb {

struct PictureSearchOptions {
  PictureOptions picture;  // how the picture becomes evidence
  SearchOptions search;    // the search of its edges (top_k, hand, per-shape limit, ...)
  LandmarkRankOptions landmark_rank;
  // The database's rig (LoadDatabaseRig): set, the matches' poses are fitted to the picture
  // (pose/fit_matches.h); null, the answer is the stored views alone.
  std::shared_ptr<const DatabaseRig> rig;
  MatchFitOptions fit;
  bool Check() const;
};

struct PictureMatches {
  PictureEvidence evidence;
  std::vector<Match> matches;   // best first
  bool landmarks_used = false;  // the landmarks re-ranked the matches (UsesLandmarks)
  PictureFit fit;               // with PictureSearchOptions::rig: the first matches' fits
};

// ReadPicture, then SearchEvidence, then (with options.rig) FitPictureMatches. Errors:
// kInvalidArgument (options), ReadPicture's and Search's.
Result<PictureMatches> SearchPicture(const Searcher& searcher,
                                     const std::filesystem::path& picture,
                                     const PictureSearchOptions& options,
                                     SearchStats* stats = nullptr);

}  // namespace handdb
