#include "evaluate/photos.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <sstream>

#include "base/json_number.h"
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

// The top-1 shape of an outcome as the confusion matrix names it.
std::string Top1Label(const PhotoOutcome& o) {
  if (!o.error.empty() || o.match_shapes.empty()) return kNoHandLabel;
  return o.match_shapes[0];
}

json DistancesToJson(const std::array<double, kNumKeypoints>& d) {
  json a = json::array();
  for (double v : d) a.push_back(NumberOrNull(v));
  return a;
}

std::array<double, kNumKeypoints> DistancesFromJson(const json& a) {
  std::array<double, kNumKeypoints> d{};
  for (int k = 0; k < kNumKeypoints; ++k) d[k] = NumberOrNaN(a.at(k));
  return d;
}

// A match's 21 keypoints in the query picture's pixels: its label is already in the query's
// normalised frame (rolled, and mirrored back for a left hand), so the query's inverse
// normalisation places it, exactly as `handdb query --json` writes keypoints_image_px.
std::vector<Point2f> ImageKeypoints(const QueryEdges& query, const ViewLabel& label) {
  std::vector<Point2f> px;
  px.reserve(kNumKeypoints);
  for (const auto& k : label.keypoints) px.push_back(query.ImageFromNormalised({k[0], k[1]}));
  return px;
}

json SummaryJson(const PhotoKeypointSummary& s) {
  json pck = json::array();
  for (size_t t = 0; t < kPckThresholds.size(); ++t) {
    pck.push_back({{"threshold", kPckThresholds[t]}, {"rate", s.pck[t]}});
  }
  return {{"photos", s.error.count},
          {"mean", NumberOrNull(s.error.mean)},
          {"median", NumberOrNull(s.error.median)},
          {"p90", NumberOrNull(s.error.p90)},
          {"pck", pck}};
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
      set.photos.push_back(
          {entry.path(), name + "/" + entry.path().filename().string(), name, std::nullopt});
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

Status AttachPhotoKeypoints(const PhotoKeypointFile& file, PhotoSet* set) {
  std::map<std::string, size_t> index;
  for (size_t i = 0; i < set->photos.size(); ++i) index[set->photos[i].relative] = i;
  const std::set<std::string> skipped(set->skipped_folders.begin(), set->skipped_folders.end());
  for (const auto& [key, keypoints] : file.images) {
    if (auto it = index.find(key); it != index.end()) {
      set->photos[it->second].keypoints = keypoints;
      continue;
    }
    const fs::path path = set->dir / key;
    std::error_code ec;
    const bool is_file = fs::is_regular_file(path, ec);
    if (is_file && skipped.count(key.substr(0, key.find('/'))) > 0) continue;
    const std::string where = file.path.string() + ": images[\"" + key + "\"]: ";
    if (!is_file) {
      return Status(StatusCode::kInvalidArgument,
                    where + "no such image in " + set->dir.string() +
                        " (keys are photo paths relative to it: <shape folder>/<file>)");
    }
    return Status(StatusCode::kInvalidArgument,
                  where + "not one of the photos evaluated (" + set->dir.string() +
                      "/<shape folder>/<image file>)");
  }
  set->keypoints_file = file.path;
  return Status::Ok();
}

double PhotoKeypointResult::top1_error() const { return MeanKeypointError(top1_px, hand_size_px); }

double PhotoKeypointResult::best10_error() const {
  return MeanKeypointError(best10_px, hand_size_px);
}

json PhotoOutcome::ToJson() const {
  json hands = json::array();
  for (Hand h : match_hands) hands.push_back(std::string(HandName(h)));
  json j = {{"photo", photo},
            {"expected_shape", expected_shape},
            {"rank", ShapeRank(*this)},
            {"match_shapes", match_shapes},
            {"match_distances", match_distances},
            {"match_hands", hands},
            {"annotated_keypoints", annotated_keypoints},
            {"input_seconds", input_seconds},
            {"search_seconds", search_seconds}};
  if (!error.empty()) j["error"] = error;
  if (top1_view != kInvalidViewId) {
    json kps = json::array();
    for (const Point2f& p : top1_keypoints_px) kps.push_back({p.x, p.y});
    j["top1"] = {{"view_id", top1_view},
                 {"roll", top1_roll},
                 {"hand", match_hands.empty() ? "right" : std::string(HandName(match_hands[0]))},
                 {"keypoints_image_px", kps}};
  }
  if (keypoints) {
    j["keypoints"] = {{"hand_size_px", keypoints->hand_size_px},
                      {"top1_error", NumberOrNull(keypoints->top1_error())},
                      {"best10_error", NumberOrNull(keypoints->best10_error())},
                      {"best10_rank", keypoints->best10_rank},
                      {"top1_distances_px", DistancesToJson(keypoints->top1_px)},
                      {"best10_distances_px", DistancesToJson(keypoints->best10_px)}};
  }
  return j;
}

Result<PhotoOutcome> PhotoOutcome::FromJson(const json& j, const std::string& where) {
  try {
    PhotoOutcome o;
    o.photo = j.at("photo").get<std::string>();
    o.expected_shape = j.at("expected_shape").get<std::string>();
    if (j.contains("error")) o.error = j.at("error").get<std::string>();
    o.match_shapes = j.at("match_shapes").get<std::vector<std::string>>();
    o.match_distances = j.at("match_distances").get<std::vector<double>>();
    for (const json& h : j.at("match_hands")) {
      auto hand = ParseHand(h.get<std::string>());
      if (!hand.ok()) return Status(StatusCode::kSchemaViolation, where + ": " + h.dump());
      o.match_hands.push_back(*hand);
    }
    o.annotated_keypoints = j.at("annotated_keypoints").get<int>();
    o.input_seconds = j.at("input_seconds").get<double>();
    o.search_seconds = j.at("search_seconds").get<double>();
    if (j.contains("top1")) {
      const json& t = j.at("top1");
      o.top1_view = t.at("view_id").get<view_id_t>();
      o.top1_roll = t.at("roll").get<roll_id_t>();
      for (const json& p : t.at("keypoints_image_px")) {
        o.top1_keypoints_px.push_back({p.at(0).get<float>(), p.at(1).get<float>()});
      }
    }
    if (j.contains("keypoints")) {
      const json& k = j.at("keypoints");
      PhotoKeypointResult r;
      r.hand_size_px = k.at("hand_size_px").get<double>();
      r.best10_rank = k.at("best10_rank").get<int>();
      r.top1_px = DistancesFromJson(k.at("top1_distances_px"));
      r.best10_px = DistancesFromJson(k.at("best10_distances_px"));
      o.keypoints = r;
    }
    if (o.match_distances.size() != o.match_shapes.size() ||
        o.match_hands.size() != o.match_shapes.size()) {
      return Status(StatusCode::kSchemaViolation,
                    where + ": match_shapes, match_distances and match_hands differ in length");
    }
    return o;
  } catch (const json::exception& e) {
    return Status(StatusCode::kSchemaViolation, where + ": " + e.what());
  }
}

double ChanceOfShapeAmongFirstK(const std::map<std::string, uint64_t>& views_per_shape,
                                const std::string& shape,
                                int k) {
  const auto it = views_per_shape.find(shape);
  if (it == views_per_shape.end() || it->second == 0 || k < 1) return 0;
  std::vector<double> others;
  for (const auto& [name, n] : views_per_shape) {
    if (name != shape && n > 0) others.push_back(static_cast<double>(n));
  }
  if (static_cast<size_t>(k) > others.size()) return 1;
  // With x = -ln(1 - t): P(T_s < t) = 1 - exp(-n_s x) and the density of T_r dt is
  // n_r exp(-n_r x) dx; with y = n_r x the integral is of exp(-y) P(fewer than k others by y /
  // n_r) over y >= 0, by the midpoint rule up to y = 40 (exp(-40): nothing left).
  const double n_r = static_cast<double>(it->second);
  // With s = 1 - (1 - t)^n_r, uniform on [0, 1) (T_r's own distribution), P(T_o < t) =
  // 1 - (1 - s)^(n_o / n_r); the probability is the integral over s of P(fewer than k others
  // first) (a Poisson-binomial recursion), by adaptive Simpson: the integrand is monotone and
  // bounded, steep near 0 when other shapes are much larger.
  std::vector<double> fewer(static_cast<size_t>(k));
  auto g = [&](double u) {
    std::fill(fewer.begin(), fewer.end(), 0.0);
    fewer[0] = 1;
    const double log_rest = std::log1p(-u);
    for (double n_o : others) {
      const double q = std::exp(log_rest * n_o / n_r);  // P(T_o >= t)
      for (int j = k - 1; j >= 1; --j) fewer[j] = fewer[j] * q + fewer[j - 1] * (1 - q);
      fewer[0] *= q;
    }
    double below_k = 0;
    for (double f : fewer) below_k += f;
    return below_k;
  };
  // One Simpson panel [a, b] (ends and middle already evaluated), halved until the two halves
  // agree with the whole to 1e-10.
  auto simpson =
      [&](auto& self, double a, double b, double fa, double fm, double fb, double whole, int depth)
      -> double {
    const double m = (a + b) / 2;
    const double flm = g((a + m) / 2);
    const double frm = g((m + b) / 2);
    const double left = (m - a) / 6 * (fa + 4 * flm + fm);
    const double right = (b - m) / 6 * (fm + 4 * frm + fb);
    if (depth <= 0 || std::abs(left + right - whole) <= 1e-10) {
      return left + right + (left + right - whole) / 15;
    }
    return self(self, a, m, fa, flm, fm, left, depth - 1) +
           self(self, m, b, fm, frm, fb, right, depth - 1);
  };
  const double hi = 1 - 1e-15;  // g(1) is the limit: every other shape has come
  const double f0 = g(0), fm = g(hi / 2), f1 = g(hi);
  const double sum = simpson(simpson, 0, hi, f0, fm, f1, hi / 6 * (f0 + 4 * fm + f1), 40);
  return std::clamp(sum, 0.0, 1.0);
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
  CHECK_OPTION(hand == Hand::kRight || hand == Hand::kLeft || hand == Hand::kEither);
  CHECK_OPTION(max_per_shape == 0 || max_per_shape == 1);
  return true;
}

namespace {

// The 2D keypoint summaries of the annotated photos (evaluate/photo_keypoints.h).
void FinishKeypointSummaries(PhotoReport* report) {
  PhotoReport& r = *report;
  r.annotated_photos = 0;
  r.annotated_failed = 0;
  const size_t nt = kPckThresholds.size();
  std::vector<double> top1, best10;
  std::vector<int64_t> top1_within(nt, 0), best10_within(nt, 0);
  int64_t visible = 0;
  auto count_within = [&](const std::array<double, kNumKeypoints>& d,
                          double hand_size,
                          std::vector<int64_t>* within) {
    for (double v : d) {
      for (size_t t = 0; t < nt; ++t) {
        if (std::isfinite(v) && v <= kPckThresholds[t] * hand_size) ++(*within)[t];
      }
    }
  };
  for (const PhotoOutcome& o : r.outcomes) {
    if (o.annotated_keypoints <= 0) continue;
    ++r.annotated_photos;
    visible += o.annotated_keypoints;
    if (!o.keypoints) {
      ++r.annotated_failed;
      continue;
    }
    top1.push_back(o.keypoints->top1_error());
    best10.push_back(o.keypoints->best10_error());
    count_within(o.keypoints->top1_px, o.keypoints->hand_size_px, &top1_within);
    count_within(o.keypoints->best10_px, o.keypoints->hand_size_px, &best10_within);
  }
  r.top1_keypoints.error = Summarise(top1);
  r.best10_keypoints.error = Summarise(best10);
  r.top1_keypoints.pck.assign(nt, 0);
  r.best10_keypoints.pck.assign(nt, 0);
  for (size_t t = 0; t < nt && visible > 0; ++t) {
    r.top1_keypoints.pck[t] = static_cast<double>(top1_within[t]) / static_cast<double>(visible);
    r.best10_keypoints.pck[t] =
        static_cast<double>(best10_within[t]) / static_cast<double>(visible);
  }
}

}  // namespace

void FinishPhotoReport(PhotoReport* report) {
  PhotoReport& r = *report;
  for (int k : r.ks) {
    THROW_CHECK_GE(k, 1);
    THROW_CHECK_LE(k, r.top_k);
  }
  std::sort(r.outcomes.begin(), r.outcomes.end(), [](const PhotoOutcome& a, const PhotoOutcome& b) {
    return a.photo < b.photo;
  });
  const size_t nk = r.ks.size();
  r.hits.assign(nk, 0);
  r.accuracy.assign(nk, 0);
  r.chance.assign(nk, 0);
  r.failed_inputs = 0;
  r.top1_left = 0;
  r.top1_right = 0;
  r.input_seconds = 0;
  r.search_seconds = 0;
  std::map<std::string, PhotoShapeRow> rows;
  std::map<std::string, std::map<std::string, int64_t>> wrong;  // expected -> top-1 -> count
  std::set<std::string> top1_others;
  std::map<std::pair<std::string, int>, double> shape_chance;  // (shape, k) -> chance
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
      if (r.max_per_shape == 1) {
        const auto key = std::make_pair(o.expected_shape, r.ks[i]);
        auto c = shape_chance.find(key);
        if (c == shape_chance.end()) {
          c = shape_chance
                  .emplace(key,
                           ChanceOfShapeAmongFirstK(
                               r.virtual_views_per_shape, o.expected_shape, r.ks[i]))
                  .first;
        }
        r.chance[i] += c->second;
      } else {
        r.chance[i] +=
            ChanceOfCorrectInTopN(r.database_virtual_views, right, static_cast<uint64_t>(r.ks[i]));
      }
    }
    const std::string top1 = Top1Label(o);
    if (top1 != o.expected_shape) ++wrong[o.expected_shape][top1];
    top1_others.insert(top1);
    if (!o.error.empty()) ++r.failed_inputs;
    if (o.error.empty() && !o.match_hands.empty()) {
      ++(o.match_hands[0] == Hand::kLeft ? r.top1_left : r.top1_right);
    }
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
  FinishKeypointSummaries(&r);
  const double searched = n - static_cast<double>(r.failed_inputs);
  r.queries_per_second = r.search_seconds > 0 ? searched / r.search_seconds : 0;
  const double e2e = r.search_seconds + r.input_seconds;
  r.end_to_end_queries_per_second = e2e > 0 ? n / e2e : 0;
}

PhotoReport StartPhotoReport(const Database& db,
                             const PhotoSet& photos,
                             const PhotoEvaluationOptions& options) {
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
  report.hand = options.hand;
  report.max_per_shape = options.max_per_shape;
  report.keypoints_file = photos.keypoints_file.string();
  report.threads = ResolveNumThreads(options.num_threads);
  return report;
}

Result<std::vector<PhotoOutcome>> ScorePhotos(const Searcher& searcher,
                                              const PhotoSet& photos,
                                              const PhotoQueryFn& query_fn,
                                              const PhotoEvaluationOptions& options,
                                              std::span<const uint32_t> positions) {
  if (!options.Check()) return Status(StatusCode::kInvalidArgument, "invalid photo options");
  for (uint32_t i : positions) THROW_CHECK_LT(i, photos.photos.size());
  SearchOptions search;
  search.top_k = kPhotoMatches;
  search.hand = options.hand;
  search.max_per_shape = options.max_per_shape;
  search.num_threads = 1;  // photos run in parallel: no synchronisation inside a search
  std::vector<PhotoOutcome> outcomes(positions.size());
  Progress progress("photos", positions.size(), options.progress, "photos");
  ParallelFor(positions.size(), ResolveNumThreads(options.num_threads), [&](size_t n, int) {
    const PhotoItem& item = photos.photos[positions[n]];
    PhotoOutcome& o = outcomes[n];
    o.photo = item.relative;
    o.expected_shape = item.expected_shape;
    if (item.keypoints) o.annotated_keypoints = item.keypoints->NumVisible();
    auto t = std::chrono::steady_clock::now();
    auto query = query_fn(item);
    o.input_seconds = SecondsSince(t);
    if (!query.ok()) {
      o.error = query.status().message();
      progress.Add();
      return true;
    }
    std::vector<Point2f> points = query->edges.points_px();
    t = std::chrono::steady_clock::now();
    auto matches = SearchEvidence(searcher, *query, search, options.landmark_rank);
    o.search_seconds = SecondsSince(t);
    if (!matches.ok()) {
      // A query that the search rejects (e.g. empty) is a failed input like "no hand".
      o.error = item.path.string() + ": " + matches.status().message();
      progress.Add();
      return true;
    }
    for (const Match& m : *matches) {
      o.match_shapes.push_back(m.shape_name);
      o.match_distances.push_back(m.distance);
      o.match_hands.push_back(m.hand);
    }
    if (!matches->empty()) {
      const Match& best = matches->front();
      o.top1_view = best.view_id;
      o.top1_roll = best.roll;
      o.top1_keypoints_px = ImageKeypoints(query->edges, best.label);
      if (item.keypoints) {
        PhotoKeypointResult r;
        r.hand_size_px = item.keypoints->hand_size_px;
        r.top1_px = KeypointDistancesPx(*item.keypoints, o.top1_keypoints_px);
        double best_error = std::numeric_limits<double>::infinity();
        const size_t n_best = std::min<size_t>(kPhotoMatches, matches->size());
        for (size_t k = 0; k < n_best; ++k) {
          const auto d = KeypointDistancesPx(*item.keypoints,
                                             ImageKeypoints(query->edges, (*matches)[k].label));
          const double e = MeanKeypointError(d, r.hand_size_px);
          if (e < best_error) {  // ties keep the better-ranked match
            best_error = e;
            r.best10_px = d;
            r.best10_rank = static_cast<int>(k) + 1;
          }
        }
        o.keypoints = r;
      }
    }
    o.query_points = std::move(points);
    progress.Add();
    return true;
  });
  progress.Finish();
  return outcomes;
}

Result<PhotoReport> EvaluatePhotos(const Searcher& searcher,
                                   const PhotoSet& photos,
                                   const PhotoQueryFn& query_fn,
                                   const PhotoEvaluationOptions& options) {
  if (!options.Check()) return Status(StatusCode::kInvalidArgument, "invalid photo options");
  const auto t0 = std::chrono::steady_clock::now();
  PhotoReport report = StartPhotoReport(searcher.database(), photos, options);
  std::vector<uint32_t> all(photos.photos.size());
  for (uint32_t i = 0; i < all.size(); ++i) all[i] = i;
  auto outcomes = ScorePhotos(searcher, photos, query_fn, options, all);
  if (!outcomes.ok()) return outcomes.status();
  report.outcomes = std::move(*outcomes);
  FinishPhotoReport(&report);
  report.wall_seconds = SecondsSince(t0);
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
  for (const PhotoOutcome& o : r.outcomes) photos.push_back(o.ToJson());
  json per_shape = json::object();
  for (const auto& [shape, count] : r.virtual_views_per_shape) per_shape[shape] = count;
  json keypoints = nullptr;
  if (!r.keypoints_file.empty()) {
    keypoints = {{"file", r.keypoints_file},
                 {"annotated_photos", r.annotated_photos},
                 {"annotated_without_query", r.annotated_failed},
                 {"hand_size", kHandSizeRule},
                 {"error_rule",
                  "mean 2D distance over the visible annotated keypoints / hand size, the "
                  "match's keypoints in the photo's pixels (mirrored back for a left hand); "
                  "mean and median over annotated photos with a usable query"},
                 {"pck_rule",
                  "share of all visible annotated keypoints within threshold x hand size; the "
                  "keypoints of annotated photos without a usable query count as missed"},
                 {"top1", SummaryJson(r.top1_keypoints)},
                 {"best_of_top10", SummaryJson(r.best10_keypoints)}};
  }
  return {{"format", "handdb-photo-evaluation"},
          {"version", 2},
          {"database",
           {{"path", r.database},
            {"views", r.database_views},
            {"rolls", r.database_rolls},
            {"virtual_views", r.database_virtual_views},
            {"virtual_views_per_shape", per_shape}}},
          {"photos_dir", r.photos_dir},
          {"skipped_folders", r.skipped_folders},
          {"search",
           {{"hand", std::string(HandName(r.hand))},
            {"top_k", r.top_k},
            {"rank", r.max_per_shape == 1 ? "shapes" : "views"},
            {"query_options", r.query_options}}},
          {"photo_count", r.outcomes.size()},
          {"failed_inputs", r.failed_inputs},
          {"top1_hands", {{"right", r.top1_right}, {"left", r.top1_left}}},
          {"chance_rule",
           r.max_per_shape == 1
               ? "mean over photos of P(the expected shape among the first k distinct shapes of a "
                 "random ordering of the virtual views)"
               : "mean over photos of 1 - C(n-m,k)/C(n,k): n virtual views, m of the expected "
                 "shape"},
          {"accuracy", accuracy},
          {"shapes", shapes},
          {"confusion",
           {{"rows", r.confusion_rows}, {"cols", r.confusion_cols}, {"counts", r.confusion}}},
          {"keypoints", keypoints},
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
  os << "search    exact top " << r.top_k
     << (r.max_per_shape == 1 ? " shapes (one match per shape, --rank shapes)"
                              : " views (--rank views)")
     << ", --hand " << HandName(r.hand);
  switch (r.hand) {
    case Hand::kRight:
      os << " (photos searched as right hands, the database's)";
      break;
    case Hand::kLeft:
      os << " (photos mirrored: searched as left hands)";
      break;
    case Hand::kEither:
      os << " (each photo and its mirror image)";
      break;
  }
  os << "; top-1 match a right hand " << r.top1_right << ", a left hand " << r.top1_left << "\n";
  os << (r.max_per_shape == 1
             ? "\nshape accuracy (the expected shape among the k nearest shapes)\n"
             : "\nshape accuracy (the expected shape among the shapes of the k nearest views)\n");
  os << "          ";
  for (int k : r.ks) os << Fmt("   top-%-3.0f", k);
  os << "\n  photos  ";
  for (size_t i = 0; i < r.ks.size(); ++i) os << Fmt("  %6.1f%%", 100.0 * r.accuracy[i]) << " ";
  os << "\n  chance  ";
  for (size_t i = 0; i < r.ks.size(); ++i) os << Fmt("  %6.1f%%", 100.0 * r.chance[i]) << " ";
  os << (r.max_per_shape == 1 ? "  (shapes met first in a random ordering of the database)\n"
                              : "  (random ordering of the database's (view, roll) pairs)\n");
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
  if (!r.keypoints_file.empty()) {
    os << "\n2D keypoints (" << r.keypoints_file << "): " << r.annotated_photos << " of "
       << r.outcomes.size() << " photos annotated\n"
       << "  error = mean distance over the visible annotated keypoints / hand size, hand size =\n"
       << "  " << kHandSizeRule << "\n";
    std::snprintf(line, sizeof line, "  %-16s %6s %7s %7s", "", "photos", "mean", "median");
    os << line;
    for (double t : kPckThresholds) os << Fmt("  PCK@%-4g", t);
    os << "\n";
    auto row = [&](const char* name, const PhotoKeypointSummary& s) {
      std::snprintf(
          line, sizeof line, "  %-16s %6lld", name, static_cast<long long>(s.error.count));
      os << line;
      for (double v : {s.error.mean, s.error.median}) {
        os << (std::isfinite(v) ? Fmt(" %7.3f", v) : std::string("       -"));
      }
      for (double p : s.pck) os << Fmt("  %7.1f%%", 100.0 * p);
      os << "\n";
    };
    row("top-1", r.top1_keypoints);
    row("best of top 10", r.best10_keypoints);
    if (r.annotated_failed > 0) {
      os << "  " << r.annotated_failed
         << " annotated photos without a usable query: in PCK as missed keypoints, not in the "
            "mean and median\n";
    }
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
                              const fs::path& dir,
                              const PhotoQueryFn& query_fn) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status(StatusCode::kIoError, dir.string() + ": " + ec.message());
  Status s = WriteConfusionPng(dir / "confusion.png", report);
  if (!s.ok()) return s;
  std::map<std::string, const PhotoItem*> item_of;
  for (const PhotoItem& item : photos.photos) item_of[item.relative] = &item;
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
      const auto item = item_of.find(o->photo);
      if (item != item_of.end()) t.image = item->second->path;
      if (!o->error.empty()) {
        t.caption2 = "no query: " + o->error.substr(o->error.find_last_of(':') == std::string::npos
                                                        ? 0
                                                        : o->error.find_last_of(':') + 2);
      } else {
        const bool left = !o->match_hands.empty() && o->match_hands[0] == Hand::kLeft;
        t.caption2 = "top-1 " + Top1Label(*o) + (left ? " (left)" : "") +
                     Fmt("  D=%.2f", o->match_distances[0]) + "  shape rank " +
                     (ShapeRank(*o) ? std::to_string(ShapeRank(*o)) : ">10");
        t.query_points = o->query_points;
        t.skeleton_px = o->top1_keypoints_px;
        if (t.query_points.empty() && query_fn && item != item_of.end()) {
          // A report merged from Slurm parts: the query again (deterministic).
          auto query = query_fn(*item->second);
          if (query.ok()) t.query_points = query->edges.points_px();
        }
        if (o->top1_view != kInvalidViewId) {
          RollPoints(
              db.points(o->top1_view), RollAngle(o->top1_roll, db.num_rolls()), &t.match_points);
          // A left-hand match is the mirrored view: drawn in the photo's frame.
          if (left) {
            for (Point2f& p : t.match_points) p.x = -p.x;
          }
        }
      }
      tiles.push_back(std::move(t));
    }
    const std::string title =
        success ? "successes: top-1 has the expected shape (its skeleton on the photo; blue photo "
                  "edges, red match)"
                : "failures: top-1 has another shape (its skeleton on the photo; blue photo edges, "
                  "red match)";
    s = WriteExampleSheetPng(dir / (success ? "successes.png" : "failures.png"), tiles, title);
    if (!s.ok()) return s;
  }
  return Status();
}

}  // namespace handdb
