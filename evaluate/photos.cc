#include "evaluate/photos.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <set>
#include <sstream>

#include "base/progress.h"
#include "base/thread_pool.h"
#include "evaluate/evaluate.h"
#include "evaluate/plots.h"
#include "format/roll.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string Fmt(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The top-1 shape of an outcome as the confusion matrix names it.
std::string Top1Label(const PhotoOutcome& o) {
  if (!o.error.empty() || o.match_shapes.empty()) return kNoHandLabel;
  return o.match_shapes[0];
}

}  // namespace

bool IsPhotoFile(const fs::path& path) {
  static const std::set<std::string> kExtensions = {
      ".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"};
  return kExtensions.count(Lower(path.extension().string())) > 0;
}

Result<PhotoSet> ListPhotoFolders(const fs::path& dir,
                                  std::span<const std::string> shape_names,
                                  bool skip_unknown) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return Status(StatusCode::kNotFound, dir.string() + ": no such photo directory");
  }
  const std::set<std::string> shapes(shape_names.begin(), shape_names.end());
  PhotoSet set;
  set.dir = dir;
  std::vector<fs::path> folders;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (entry.is_directory()) folders.push_back(entry.path());
  }
  if (ec) return Status(StatusCode::kIoError, dir.string() + ": " + ec.message());
  std::sort(folders.begin(), folders.end());
  for (const fs::path& folder : folders) {
    const std::string name = folder.filename().string();
    if (shapes.count(name) == 0) {
      if (skip_unknown) {
        set.skipped_folders.push_back(name);
        continue;
      }
      return Status(StatusCode::kInvalidArgument,
                    folder.string() + ": '" + name +
                        "' is not a shape of the database (folders must be named after its "
                        "shapes; --skip-unknown skips such folders)");
    }
    for (const auto& entry : fs::directory_iterator(folder, ec)) {
      if (!entry.is_regular_file() || !IsPhotoFile(entry.path())) continue;
      set.photos.push_back({entry.path(), name + "/" + entry.path().filename().string(), name});
    }
    if (ec) return Status(StatusCode::kIoError, folder.string() + ": " + ec.message());
  }
  if (set.photos.empty()) {
    return Status(StatusCode::kInvalidArgument,
                  dir.string() + ": no photos (expected DIR/<shape name>/<image>.jpg|png|...)");
  }
  std::sort(set.photos.begin(), set.photos.end(), [](const PhotoItem& a, const PhotoItem& b) {
    return a.relative < b.relative;
  });
  return set;
}

int ShapeRank(const PhotoOutcome& outcome) {
  if (!outcome.error.empty()) return 0;
  for (size_t i = 0; i < outcome.match_shapes.size(); ++i) {
    if (outcome.match_shapes[i] == outcome.expected_shape) return static_cast<int>(i) + 1;
  }
  return 0;
}

bool PhotoEvaluationOptions::Check() const {
  CHECK_OPTION(num_threads == -1 || num_threads >= 1);
  return true;
}

void FinishPhotoReport(PhotoReport* report) {
  PhotoReport& r = *report;
  for (int k : r.ks) THROW_CHECK_GE(k, 1);
  std::sort(r.outcomes.begin(), r.outcomes.end(), [](const PhotoOutcome& a, const PhotoOutcome& b) {
    return a.photo < b.photo;
  });
  const size_t nk = r.ks.size();
  r.hits.assign(nk, 0);
  r.accuracy.assign(nk, 0);
  r.chance.assign(nk, 0);
  r.failed_inputs = 0;
  r.input_seconds = 0;
  r.search_seconds = 0;
  std::map<std::string, PhotoShapeRow> rows;
  std::map<std::string, std::map<std::string, int64_t>> wrong;  // expected -> top-1 -> count
  std::set<std::string> top1_others;
  for (const PhotoOutcome& o : r.outcomes) {
    const int rank = ShapeRank(o);
    PhotoShapeRow& row = rows[o.expected_shape];
    row.shape = o.expected_shape;
    row.hits.resize(nk, 0);
    ++row.photos;
    for (size_t i = 0; i < nk; ++i) {
      if (rank >= 1 && rank <= r.ks[i]) {
        ++r.hits[i];
        ++row.hits[i];
      }
      const auto it = r.virtual_views_per_shape.find(o.expected_shape);
      const uint64_t right = it == r.virtual_views_per_shape.end() ? 0 : it->second;
      r.chance[i] +=
          ChanceOfCorrectInTopN(r.database_virtual_views, right, static_cast<uint64_t>(r.ks[i]));
    }
    const std::string top1 = Top1Label(o);
    if (top1 != o.expected_shape) ++wrong[o.expected_shape][top1];
    top1_others.insert(top1);
    if (!o.error.empty()) ++r.failed_inputs;
    r.input_seconds += o.input_seconds;
    r.search_seconds += o.search_seconds;
  }
  const double n = static_cast<double>(r.outcomes.size());
  for (size_t i = 0; i < nk && n > 0; ++i) {
    r.accuracy[i] = static_cast<double>(r.hits[i]) / n;
    r.chance[i] /= n;
  }
  r.shapes.clear();
  r.confusion_rows.clear();
  for (auto& [shape, row] : rows) {
    // std::map iterates alphabetically, so a tie goes to the first name.
    for (const auto& [label, count] : wrong[shape]) {
      if (count > row.top_wrong_count) {
        row.top_wrong = label;
        row.top_wrong_count = count;
      }
    }
    r.confusion_rows.push_back(shape);
    r.shapes.push_back(row);
  }
  r.confusion_cols = r.confusion_rows;
  for (const std::string& s : top1_others) {
    if (s != kNoHandLabel && !rows.count(s)) r.confusion_cols.push_back(s);
  }
  if (top1_others.count(kNoHandLabel)) r.confusion_cols.push_back(kNoHandLabel);
  std::map<std::string, size_t> col_index;
  for (size_t c = 0; c < r.confusion_cols.size(); ++c) col_index[r.confusion_cols[c]] = c;
  std::map<std::string, size_t> row_index;
  for (size_t i = 0; i < r.confusion_rows.size(); ++i) row_index[r.confusion_rows[i]] = i;
  r.confusion.assign(r.confusion_rows.size(), std::vector<int64_t>(r.confusion_cols.size(), 0));
  for (const PhotoOutcome& o : r.outcomes) {
    ++r.confusion[row_index.at(o.expected_shape)][col_index.at(Top1Label(o))];
  }
  const double searched = n - static_cast<double>(r.failed_inputs);
  r.queries_per_second = r.search_seconds > 0 ? searched / r.search_seconds : 0;
  const double e2e = r.search_seconds + r.input_seconds;
  r.end_to_end_queries_per_second = e2e > 0 ? n / e2e : 0;
}

Result<PhotoReport> EvaluatePhotos(const Searcher& searcher,
                                   const PhotoSet& photos,
                                   const PhotoPointsFn& points_fn,
                                   const PhotoEvaluationOptions& options) {
  if (!options.Check()) return Status(StatusCode::kInvalidArgument, "invalid photo options");
  const auto t0 = std::chrono::steady_clock::now();
  const Database& db = searcher.database();
  PhotoReport report;
  report.database = db.path().string();
  report.database_views = db.num_views();
  report.database_rolls = db.num_rolls();
  report.database_virtual_views = db.num_virtual_views();
  for (view_id_t v = 0; v < db.num_views(); ++v) {
    const std::string name(db.shape_name(db.label(v).shape_id));
    report.virtual_views_per_shape[name] += db.num_rolls();
  }
  report.photos_dir = photos.dir.string();
  report.skipped_folders = photos.skipped_folders;
  const int top_k = *std::max_element(report.ks.begin(), report.ks.end());
  const int threads = ResolveNumThreads(options.num_threads);
  report.threads = threads;
  report.outcomes.resize(photos.photos.size());
  Progress progress("photos", photos.photos.size(), options.progress, "photos");
  SearchOptions search;
  search.top_k = top_k;
  search.num_threads = 1;  // photos run in parallel: no synchronisation inside a search
  Status error;
  std::mutex mu;
  ParallelFor(photos.photos.size(), threads, [&](size_t i, int) {
    const PhotoItem& item = photos.photos[i];
    PhotoOutcome& o = report.outcomes[i];
    o.photo = item.relative;
    o.expected_shape = item.expected_shape;
    auto t = std::chrono::steady_clock::now();
    auto points = points_fn(item);
    o.input_seconds = Seconds(t);
    if (!points.ok()) {
      o.error = points.status().message();
      progress.Add();
      return true;
    }
    t = std::chrono::steady_clock::now();
    auto matches = searcher.Search(*points, search);
    o.search_seconds = Seconds(t);
    if (!matches.ok()) {
      // A query that the search rejects (e.g. empty) is a failed input like "no hand".
      o.error = item.path.string() + ": " + matches.status().message();
      progress.Add();
      return true;
    }
    for (const Match& m : *matches) {
      o.match_shapes.push_back(m.shape_name);
      o.match_distances.push_back(m.distance);
    }
    if (!matches->empty()) {
      o.top1_view = (*matches)[0].view_id;
      o.top1_roll_angle = (*matches)[0].roll_angle;
    }
    o.query_points = std::move(points).value();
    progress.Add();
    return true;
  });
  progress.Finish();
  FinishPhotoReport(&report);
  report.wall_seconds = Seconds(t0);
  return report;
}

json PhotoReportToJson(const PhotoReport& r) {
  json accuracy = json::array();
  for (size_t i = 0; i < r.ks.size(); ++i) {
    accuracy.push_back(
        {{"k", r.ks[i]}, {"hits", r.hits[i]}, {"rate", r.accuracy[i]}, {"chance", r.chance[i]}});
  }
  json shapes = json::array();
  for (const PhotoShapeRow& row : r.shapes) {
    json hits = json::array();
    for (size_t i = 0; i < r.ks.size(); ++i)
      hits.push_back({{"k", r.ks[i]}, {"hits", row.hits[i]}});
    shapes.push_back({{"shape", row.shape},
                      {"photos", row.photos},
                      {"hits", hits},
                      {"top_wrong", row.top_wrong},
                      {"top_wrong_count", row.top_wrong_count}});
  }
  json photos = json::array();
  for (const PhotoOutcome& o : r.outcomes) {
    json p = {{"photo", o.photo},
              {"expected_shape", o.expected_shape},
              {"rank", ShapeRank(o)},
              {"match_shapes", o.match_shapes},
              {"match_distances", o.match_distances},
              {"input_seconds", o.input_seconds},
              {"search_seconds", o.search_seconds}};
    if (!o.error.empty()) p["error"] = o.error;
    photos.push_back(std::move(p));
  }
  json per_shape = json::object();
  for (const auto& [shape, count] : r.virtual_views_per_shape) per_shape[shape] = count;
  return {{"format", "handdb-photo-evaluation"},
          {"version", 1},
          {"database",
           {{"path", r.database},
            {"views", r.database_views},
            {"rolls", r.database_rolls},
            {"virtual_views", r.database_virtual_views},
            {"virtual_views_per_shape", per_shape}}},
          {"photos_dir", r.photos_dir},
          {"skipped_folders", r.skipped_folders},
          {"photo_count", r.outcomes.size()},
          {"failed_inputs", r.failed_inputs},
          {"chance_rule",
           "mean over photos of 1 - C(n-m,k)/C(n,k): n virtual views, m of the expected shape"},
          {"accuracy", accuracy},
          {"shapes", shapes},
          {"confusion",
           {{"rows", r.confusion_rows}, {"cols", r.confusion_cols}, {"counts", r.confusion}}},
          {"timing",
           {{"threads", r.threads},
            {"wall_seconds", r.wall_seconds},
            {"input_seconds", r.input_seconds},
            {"search_seconds", r.search_seconds},
            {"queries_per_second", r.queries_per_second},
            {"end_to_end_queries_per_second", r.end_to_end_queries_per_second}}},
          {"photos", photos}};
}

std::string PhotoReportToText(const PhotoReport& r) {
  std::ostringstream os;
  os << "database  " << r.database << ": " << r.database_views << " views x " << r.database_rolls
     << " rolls = " << r.database_virtual_views << " virtual views\n";
  os << "photos    " << r.photos_dir << ": " << r.outcomes.size() << " photos, " << r.shapes.size()
     << " shapes";
  if (r.failed_inputs > 0) os << ", " << r.failed_inputs << " without a usable query (misses)";
  os << "\n";
  if (!r.skipped_folders.empty()) {
    os << "skipped   folders that are not shapes of the database:";
    for (const std::string& s : r.skipped_folders) os << " " << s;
    os << "\n";
  }
  os << "\nshape accuracy (the expected shape among the shapes of the top k matches)\n";
  os << "          ";
  for (int k : r.ks) os << Fmt("   top-%-3.0f", k);
  os << "\n  photos  ";
  for (size_t i = 0; i < r.ks.size(); ++i) os << Fmt("  %6.1f%%", 100.0 * r.accuracy[i]) << " ";
  os << "\n  chance  ";
  for (size_t i = 0; i < r.ks.size(); ++i) os << Fmt("  %6.1f%%", 100.0 * r.chance[i]) << " ";
  os << "  (random ordering of the database's (view, roll) pairs)\n";
  os << "\nper shape\n";
  char line[256];
  std::snprintf(line, sizeof line, "  %-16s %5s", "shape", "n");
  os << line;
  for (int k : r.ks) os << Fmt("  top-%-2.0f", k);
  os << "  most frequent wrong top-1\n";
  for (const PhotoShapeRow& row : r.shapes) {
    std::snprintf(
        line, sizeof line, "  %-16s %5lld", row.shape.c_str(), static_cast<long long>(row.photos));
    os << line;
    for (size_t i = 0; i < r.ks.size(); ++i) {
      std::snprintf(line, sizeof line, "  %6lld", static_cast<long long>(row.hits[i]));
      os << line;
    }
    if (!row.top_wrong.empty()) {
      os << "  " << row.top_wrong << " (" << row.top_wrong_count << ")";
    }
    os << "\n";
  }
  os << "\n"
     << Fmt("speed     %.2f queries/s", r.queries_per_second)
     << Fmt(" (search only, per thread), %.2f end to end", r.end_to_end_queries_per_second)
     << Fmt("; wall %.1f s", r.wall_seconds) << " on " << r.threads << " threads\n";
  if (r.failed_inputs > 0) {
    os << "\nphotos without a usable query (counted as misses)\n";
    for (const PhotoOutcome& o : r.outcomes) {
      if (!o.error.empty()) os << "  " << o.photo << ": " << o.error << "\n";
    }
  }
  return os.str();
}

Status WriteConfusionPng(const fs::path& path, const PhotoReport& report) {
  return WriteConfusionMatrixPng(
      path,
      report.confusion_rows,
      report.confusion_cols,
      report.confusion,
      "confusion: " + std::to_string(report.outcomes.size()) + " photos, top-1 " +
          Fmt("%.1f%%", report.accuracy.empty() ? 0.0 : 100.0 * report.accuracy[0]),
      "expected shape",
      "top-1 shape");
}

Status WritePhotoReportImages(const PhotoReport& report,
                              const Searcher& searcher,
                              const PhotoSet& photos,
                              const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status(StatusCode::kIoError, dir.string() + ": " + ec.message());
  Status s = WriteConfusionPng(dir / "confusion.png", report);
  if (!s.ok()) return s;
  std::map<std::string, fs::path> path_of;
  for (const PhotoItem& item : photos.photos) path_of[item.relative] = item.path;
  const Database& db = searcher.database();
  // A handful of photos per sheet, one per shape in turn so that every shape shows up.
  constexpr size_t kTiles = 8;
  auto pick = [&](bool success) {
    std::map<std::string, std::vector<const PhotoOutcome*>> by_shape;
    for (const PhotoOutcome& o : report.outcomes) {
      if ((ShapeRank(o) == 1) == success) by_shape[o.expected_shape].push_back(&o);
    }
    std::vector<const PhotoOutcome*> chosen;
    for (size_t round = 0; chosen.size() < kTiles; ++round) {
      bool any = false;
      for (const auto& [shape, list] : by_shape) {
        if (round < list.size() && chosen.size() < kTiles) {
          chosen.push_back(list[round]);
          any = true;
        }
      }
      if (!any) break;
    }
    return chosen;
  };
  for (const bool success : {true, false}) {
    std::vector<ExampleTile> tiles;
    for (const PhotoOutcome* o : pick(success)) {
      ExampleTile t;
      t.caption = o->photo;
      t.image = path_of.count(o->photo) ? path_of.at(o->photo) : fs::path();
      if (!o->error.empty()) {
        t.caption2 = "no query: " + o->error.substr(o->error.find_last_of(':') == std::string::npos
                                                        ? 0
                                                        : o->error.find_last_of(':') + 2);
      } else {
        t.caption2 = "top-1 " + Top1Label(*o) + Fmt("  D=%.2f", o->match_distances[0]) +
                     "  shape rank " + (ShapeRank(*o) ? std::to_string(ShapeRank(*o)) : ">10");
        t.query_points = o->query_points;
        if (o->top1_view != kInvalidViewId) {
          RollPoints(db.points(o->top1_view), o->top1_roll_angle, &t.match_points);
        }
      }
      tiles.push_back(std::move(t));
    }
    const std::string title =
        success ? "successes: top-1 has the expected shape (blue photo edges, red match)"
                : "failures: top-1 has another shape (blue photo edges, red match)";
    s = WriteExampleSheetPng(dir / (success ? "successes.png" : "failures.png"), tiles, title);
    if (!s.ok()) return s;
  }
  return Status();
}

}  // namespace handdb
