// The pictures of a batch `handdb query DB IMAGE... | DIR | -`: the words after DB expanded into
// one list of picture paths, in the order the user gave them.
#pragma once

#include <istream>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"

namespace handdb::cli {

// Whether a file name has one of the extensions of the pictures a directory contributes: png,
// jpg, jpeg, exr, pnm, pgm, ppm, bmp (case-insensitive).
bool IsPictureFileName(std::string_view name);

// Whether these IMAGE words make a batch: more than one, a directory, or "-".
bool IsBatch(const std::vector<std::string>& words);

// Each word in order: "-" is the lines of `list` (one path per line; empty lines skipped, a
// trailing '\r' dropped; "-" may appear once), a directory is its picture files
// (IsPictureFileName; regular files or links to them, not recursive) sorted by name, anything
// else is itself (a missing or bad file is that picture's error, reported when it is read).
// Errors: kInvalidArgument ("-" twice), kIoError (a directory that cannot be listed),
// kNotFound (a directory without pictures).
Result<std::vector<std::string>> ListPictures(const std::vector<std::string>& words,
                                              std::istream& list);

}  // namespace handdb::cli
