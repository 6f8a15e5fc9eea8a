#include "cli/query_batch.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <filesystem>
#include <system_error>

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;

// The formats photo/image_read.h reads, by extension.
constexpr std::array<std::string_view, 8> kPictureExtensions = {
    ".png", ".jpg", ".jpeg", ".exr", ".pnm", ".pgm", ".ppm", ".bmp"};

Result<std::vector<std::string>> DirectoryPictures(const std::string& dir) {
  std::vector<std::string> found;
  std::error_code ec;
  fs::directory_iterator it(dir, ec);
  for (; !ec && it != fs::directory_iterator(); it.increment(ec)) {
    std::error_code type_ec;
    // is_regular_file follows a link, so a link to a picture counts and a dangling one does not.
    if (!it->is_regular_file(type_ec)) continue;
    if (!IsPictureFileName(it->path().filename().string())) continue;
    found.push_back(it->path().string());
  }
  if (ec) return Status(StatusCode::kIoError, dir + ": cannot list the directory: " + ec.message());
  if (found.empty()) {
    return Status(StatusCode::kNotFound,
                  dir + ": no picture files (png, jpg, jpeg, exr, pnm, pgm, ppm, bmp)");
  }
  std::sort(found.begin(), found.end());
  return found;
}

}  // namespace

bool IsPictureFileName(std::string_view name) {
  const size_t dot = name.rfind('.');
  if (dot == std::string_view::npos || dot == 0) return false;
  std::string ext(name.substr(dot));
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return std::find(kPictureExtensions.begin(), kPictureExtensions.end(), ext) !=
         kPictureExtensions.end();
}

bool IsBatch(const std::vector<std::string>& words) {
  if (words.size() != 1) return words.size() > 1;
  std::error_code ec;
  return words[0] == "-" || fs::is_directory(words[0], ec);
}

Result<std::vector<std::string>> ListPictures(const std::vector<std::string>& words,
                                              std::istream& list) {
  std::vector<std::string> pictures;
  bool read_list = false;
  for (const std::string& word : words) {
    std::error_code ec;
    if (word == "-") {
      if (read_list) {
        return Status(StatusCode::kInvalidArgument,
                      "\"-\" (the list of pictures on stdin) is given twice");
      }
      read_list = true;
      std::string line;
      while (std::getline(list, line)) {
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (!line.empty()) pictures.push_back(line);
      }
      if (list.bad()) return Status(StatusCode::kIoError, "cannot read the list on stdin");
    } else if (fs::is_directory(word, ec)) {
      auto found = DirectoryPictures(word);
      if (!found.ok()) return found.status();
      pictures.insert(pictures.end(), found->begin(), found->end());
    } else {
      pictures.push_back(word);
    }
  }
  return pictures;
}

}  // namespace handdb::cli
