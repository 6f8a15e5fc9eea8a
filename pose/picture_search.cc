#include "pose/picture_search.h"

#include <utility>

namespace handdb {

bool PictureSearchOptions::Check() const {
  CHECK_OPTION(picture.Check());
  CHECK_OPTION(search.Check());
  CHECK_OPTION(landmark_rank.Check());
  CHECK_OPTION(fit.Check());
  return true;
}

Result<PictureMatches> SearchPicture(const Searcher& searcher,
                                     const std::filesystem::path& picture,
                                     const PictureSearchOptions& options,
                                     SearchStats* stats) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument,
                  picture.string() + ": invalid picture search options (see the line above)");
  }
  auto evidence = ReadPicture(picture, options.picture);
  if (!evidence.ok()) return evidence.status();
  PictureMatches out;
  out.evidence = std::move(evidence).value();
  auto matches =
      SearchEvidence(searcher, out.evidence, options.search, options.landmark_rank, stats);
  if (!matches.ok()) return matches.status();
  out.matches = std::move(matches).value();
  out.landmarks_used = UsesLandmarks(out.evidence, options.landmark_rank);
  if (options.rig != nullptr) {
    auto fit = FitPictureMatches(
        *options.rig, searcher.database(), out.evidence, out.matches, options.fit);
    if (!fit.ok()) return fit.status();
    out.fit = std::move(fit).value();
  }
  return out;
}

}  // namespace handdb
