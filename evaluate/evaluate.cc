#include "evaluate/evaluate.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include "base/atomic_file.h"
#include "base/json_number.h"
#include "base/json_schema.h"
#include "base/progress.h"
#include "base/thread_pool.h"
#include "evaluate/plots.h"

namespace handdb {
namespace fs = std::filesystem;
namespace {

constexpr int64_t kNotApplicable = -1;

Vec3 Vec3From(const nlohmann::json& j) {
  return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()};
}

std::string FormatDouble(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

nlohmann::json SummaryToJson(const Summary& s) {
  return {{"count", s.count},
          {"mean", NumberOrNull(s.mean)},
          {"median", NumberOrNull(s.median)},
          {"p90", NumberOrNull(s.p90)},
          {"min", NumberOrNull(s.min)},
          {"max", NumberOrNull(s.max)}};
}

nlohmann::json CriterionToJson(const Criterion& c) {
  return {{"name", c.name},
          {"joint_distance", std::string(JointDistanceKindName(c.options.joint_distance))},
          {"max_joint_distance_deg", c.options.max_joint_distance_deg},
          {"max_direction_deg", c.options.max_direction_deg},
          {"max_roll_deg", c.options.max_roll_deg},
          {"roll_compare", c.options.roll_compare == RollCompare::kAligned ? "aligned" : "label"},
          {"same_shape", c.options.same_shape},
          {"basic_only", c.basic_only}};
}

nlohmann::json TableToJson(const RankTable& t) {
  nlohmann::json bins = nlohmann::json::array();
  for (int b = 0; b < kNumRankBins; ++b) bins.push_back(std::string(RankBinName(b)));
  return {{"bins", bins}, {"counts", t.counts}, {"total", t.total()}};
}

}  // namespace

namespace {
nlohmann::json ChanceToJson(const EvaluationReport& report) {
  nlohmann::json cells = nlohmann::json::array();
  for (size_t i = 0; i < report.chance_success.size(); ++i) {
    cells.push_back({{"n", report.options.success_n[i]}, {"rate", report.chance_success[i]}});
  }
  return {{"computed", !report.chance_success.empty()},
          {"mean_correct_per_view", report.mean_correct_per_view},
          {"success", cells}};
}

// A file a test set names: relative, and below the test set's directory, so a label of
// "../../etc/passwd" or "/dev/zero" is refused when the test set is read.
Result<fs::path> InsideTestSet(const fs::path& dir,
                               const std::string& relative,
                               const std::string& what,
                               const std::string& field) {
  const fs::path p(relative);
  bool escapes = p.empty() || p.is_absolute() || p.has_root_name();
  for (const fs::path& part : p) escapes = escapes || part == "..";
  if (escapes) {
    return Status(StatusCode::kOutOfRange,
                  what + ": " + field + " is \"" + relative.substr(0, 60) +
                      "\", not a relative path inside the test set's directory");
  }
  return dir / p;
}

}  // namespace

Status CheckTestSetInputs(const TestSet& testset,
                          QueryInput input,
                          std::span<const uint32_t> positions) {
  for (uint32_t i : positions) {
    if (i >= testset.views.size()) continue;  // EvaluateViews reports it
    const TestView& v = testset.views[i];
    const fs::path& file = input == QueryInput::kPhoto ? v.photo : v.label;
    if (file.empty()) {
      return Status(StatusCode::kNotFound,
                    testset.file.string() + ": test view " + std::to_string(v.id) +
                        " has no photo (render the test set with photos)");
    }
    if (Status s = CheckRegularFile(file); !s.ok()) {
      return Status(s.code(),
                    s.message() + " (" + QueryInputName(input) + " input of test view " +
                        std::to_string(v.id) + " in " + testset.file.string() + ")");
    }
  }
  return Status::Ok();
}

const char* QueryInputName(QueryInput input) {
  return input == QueryInput::kClean ? "clean" : "photo";
}

Result<TestSet> ReadTestSet(const fs::path& dir_or_file) {
  const fs::path file = fs::is_directory(dir_or_file) ? dir_or_file / "testset.json" : dir_or_file;
  auto doc = ReadJsonFile(file, "testset.schema.json");
  if (!doc.ok()) {
    if (doc.status().code() == StatusCode::kNotFound && fs::is_directory(dir_or_file)) {
      return Status(
          StatusCode::kNotFound,
          file.string() + ": no test-set ground truth (run `handdb testset` to completion)");
    }
    return doc.status();
  }
  // The schema fixed the types; ranges are checked here (a seed of 2^64 parses as a float, a
  // joint angle of 1e300 does not fit a float). Found by tests/fuzz/testset_fuzzer.cc.
  const std::string what = file.string();
  auto out_of_range = [&](const std::string& field, const nlohmann::json& value) {
    return Status(
        StatusCode::kOutOfRange,
        what + ": " + field + " is " + value.dump().substr(0, 40) + ", outside its range");
  };
  auto to_float = [&](const nlohmann::json& value, const std::string& field) -> Result<float> {
    const double d = value.get<double>();
    if (!std::isfinite(d) || std::abs(d) > std::numeric_limits<float>::max()) {
      return out_of_range(field, value);
    }
    return static_cast<float>(d);
  };
  TestSet set;
  set.dir = file.parent_path();
  set.file = file;
  try {
    set.name = doc->at("name").get<std::string>();
    // is_number_integer() holds for both signed and unsigned; the schema's minimum 0 has held.
    if (!doc->at("seed").is_number_integer()) return out_of_range("seed", doc->at("seed"));
    set.seed = doc->at("seed").get<uint64_t>();
    set.hand_model_sha256 = doc->at("hand_model").at("sha256").get<std::string>();
    set.axes.forward_axis = Vec3From(doc->at("forward_axis"));
    set.axes.palm_normal = Vec3From(doc->at("palm_normal"));
    set.clutter = doc->at("clutter").get<bool>();
    set.forearm = doc->value("forearm", false);
    const nlohmann::json& items = doc->at("items");
    for (size_t i = 0; i < items.size(); ++i) {
      const nlohmann::json& j = items[i];
      const std::string item = "items[" + std::to_string(i) + "].";
      TestView v;
      if (!j.at("id").is_number_integer() ||
          j.at("id").get<uint64_t>() > std::numeric_limits<uint32_t>::max()) {
        return out_of_range(item + "id", j.at("id"));
      }
      v.id = j.at("id").get<uint32_t>();
      v.basic = j.at("basic").get<bool>();
      v.shape_name = j.at("shape_name").get<std::string>();
      for (int k = 0; k < kNumJointAngles; ++k) {
        auto a =
            to_float(j.at("joint_angles").at(k), item + "joint_angles[" + std::to_string(k) + "]");
        if (!a.ok()) return a.status();
        v.truth.joint_angles[k] = *a;
      }
      v.truth.view_direction = Vec3From(j.at("view_direction"));
      v.truth.camera_roll = j.at("camera_roll").get<double>();
      for (int k = 0; k < kNumKeypoints; ++k) {
        for (int c = 0; c < 3; ++c) {
          auto x =
              to_float(j.at("keypoints").at(k).at(c),
                       item + "keypoints[" + std::to_string(k) + "][" + std::to_string(c) + "]");
          if (!x.ok()) return x.status();
          v.truth.keypoints[k][c] = *x;
        }
      }
      auto label = InsideTestSet(set.dir, j.at("label").get<std::string>(), what, item + "label");
      if (!label.ok()) return label.status();
      v.label = *label;
      if (j.contains("photo")) {
        auto photo = InsideTestSet(set.dir, j.at("photo").get<std::string>(), what, item + "photo");
        if (!photo.ok()) return photo.status();
        v.photo = *photo;
      }
      set.views.push_back(std::move(v));
    }
  } catch (const nlohmann::json::exception& e) {
    return Status(StatusCode::kSchemaViolation, what + ": " + e.what());
  }
  return set;
}

bool EvaluationOptions::Check() const {
  CHECK_OPTION(correctness.Check());
  CHECK_OPTION_GE(first_k, 10);  // keypoint error of the best of the top 10
  CHECK_OPTION_GE(max_rank, static_cast<int64_t>(first_k));
  CHECK_OPTION(num_threads == -1 || num_threads >= 1);
  CHECK_OPTION_GE(max_views, 0);
  CHECK_OPTION_GE(stride, 1);
  CHECK_OPTION(fit.Check());
  for (double d : d_grid_deg) CHECK_OPTION_GE(d, 0.0);
  for (int64_t n : success_n) {
    CHECK_OPTION_GE(n, 1);
    CHECK_OPTION_LE(n, max_rank);
  }
  return true;
}

double ChanceOfCorrectInTopN(uint64_t total, uint64_t correct, uint64_t n) {
  if (correct == 0 || total == 0) return 0;
  if (n >= total || correct > total - std::min(n, total)) return 1;
  // P(none in the first n) = prod_{i < n} (total - correct - i) / (total - i), in logs.
  double log_none = 0;
  for (uint64_t i = 0; i < n; ++i) {
    log_none += std::log(static_cast<double>(total - correct - i)) -
                std::log(static_cast<double>(total - i));
  }
  return 1.0 - std::exp(log_none);
}

namespace {
// Correct (view, roll) pairs of the whole database for one judge. Shape and direction depend on
// the view only, so rolls are tried only for views that pass both.
int64_t CountCorrect(const std::vector<PoseForEval>& db_poses,
                     uint32_t num_rolls,
                     const CorrectnessJudge& judge) {
  int64_t count = 0;
  for (const PoseForEval& canonical : db_poses) {
    const CorrectnessDetail detail = judge.Judge(canonical);
    if (!detail.shape_ok || !detail.direction_ok) continue;
    PoseForEval pose = canonical;
    for (roll_id_t r = 0; r < num_rolls; ++r) {
      pose.camera_roll = canonical.camera_roll + RollAngle(r, num_rolls);
      count += judge.Judge(pose).roll_ok ? 1 : 0;
    }
  }
  return count;
}
}  // namespace

std::vector<Criterion> MakeCriteria(const EvaluationOptions& options) {
  std::vector<Criterion> out;
  out.push_back({"main", options.correctness, false});
  CorrectnessOptions same = options.correctness;
  same.same_shape = true;
  out.push_back({"same-shape", same, true});
  for (double d : options.d_grid_deg) {
    CorrectnessOptions c = options.correctness;
    c.same_shape = false;
    c.max_joint_distance_deg = d;
    out.push_back({"d=" + FormatDouble("%g", d), c, false});
  }
  return out;
}

std::vector<uint32_t> SelectTestViews(const TestSet& testset, const EvaluationOptions& options) {
  std::vector<uint32_t> selected;
  const size_t stride = static_cast<size_t>(std::max(1, options.stride));
  for (size_t i = 0; i < testset.views.size(); i += stride) {
    selected.push_back(static_cast<uint32_t>(i));
  }
  if (options.max_views > 0 && selected.size() > static_cast<size_t>(options.max_views)) {
    selected.resize(static_cast<size_t>(options.max_views));
  }
  return selected;
}

EvaluationReport StartReport(const Database& db,
                             const TestSet& testset,
                             QueryInput input,
                             const EvaluationOptions& options) {
  EvaluationReport report;
  report.database = db.path().string();
  report.database_views = db.num_views();
  report.database_rolls = db.num_rolls();
  report.database_virtual_views = db.num_virtual_views();
  report.testset = testset.dir.string();
  report.testset_seed = testset.seed;
  report.input = input;
  report.options = options;
  report.criteria = MakeCriteria(options);
  report.threads = ResolveNumThreads(options.num_threads);
  return report;
}

Result<std::vector<ViewOutcome>> EvaluateViews(const Searcher& searcher,
                                               const TestSet& testset,
                                               const QueryPointsFn& query_points,
                                               const EvaluationOptions& options,
                                               std::span<const uint32_t> positions) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "evaluation options are invalid (see above)");
  }
  const Database& db = searcher.database();
  const std::vector<Criterion> criteria = MakeCriteria(options);
  const size_t num_criteria = criteria.size();
  for (uint32_t i : positions) {
    if (i >= testset.views.size()) {
      return Status(StatusCode::kOutOfRange,
                    testset.file.string() + ": no test view at position " + std::to_string(i) +
                        " (the test set has " + std::to_string(testset.views.size()) + ")");
    }
  }

  SearchOptions first;
  first.top_k = static_cast<int>(std::min<uint64_t>(options.first_k, db.num_virtual_views()));
  first.num_threads = options.num_threads;
  SearchOptions deep = first;
  deep.top_k = static_cast<int>(std::min<uint64_t>(options.max_rank, db.num_virtual_views()));

  // The canonical poses of the database (keypoints are not needed to judge correctness): every
  // test view's correct (view, roll) pairs are counted from them, which gives the chance baseline
  // and tells when a deeper search can find nothing (no correct pair exists at all).
  std::vector<PoseForEval> db_poses(db.num_views());
  std::vector<ViewLabel> db_labels;
  if (options.keypoint_floor) db_labels.reserve(db.num_views());
  for (view_id_t v = 0; v < db.num_views(); ++v) {
    const ViewLabel label = db.label(v);
    db_poses[v].joint_angles = label.joint_angles;
    db_poses[v].view_direction = {
        label.view_direction[0], label.view_direction[1], label.view_direction[2]};
    db_poses[v].camera_roll = label.camera_roll;
    if (options.keypoint_floor) db_labels.push_back(label);
  }
  // The floor of every selected view first, spread over the search's threads: it needs the truth
  // only, not the query.
  std::vector<double> floors(positions.size(), std::numeric_limits<double>::quiet_NaN());
  if (options.keypoint_floor) {
    const auto t_floor = std::chrono::steady_clock::now();
    const KeypointFloorIndex floor_index(std::move(db_labels), db.num_rolls());
    std::atomic<uint64_t> views_checked{0};
    ParallelFor(positions.size(), searcher.num_threads(), [&](size_t k, int /*worker*/) {
      const KeypointFloor f = floor_index.Floor(testset.views[positions[k]].truth.keypoints);
      floors[k] = f.error;
      views_checked += f.views_checked;
      return true;
    });
    // Its cost on stderr with the progress, not in the report: it is a fact of the run.
    if (options.progress && !positions.empty()) {
      std::fprintf(stderr,
                   "evaluate   keypoint floor of %zu test views over %llu virtual views in %.3f s "
                   "(every roll of %.1f stored views per test view)\n",
                   positions.size(),
                   static_cast<unsigned long long>(db.num_virtual_views()),
                   SecondsSince(t_floor),
                   static_cast<double>(views_checked) / static_cast<double>(positions.size()));
    }
  }

  std::vector<ViewOutcome> outcomes;
  outcomes.reserve(positions.size());
  Progress progress("evaluate", positions.size(), options.progress, "queries");
  for (size_t k = 0; k < positions.size(); ++k) {
    const uint32_t i = positions[k];
    const TestView& view = testset.views[i];
    ViewOutcome out;
    out.test_id = view.id;
    out.testset_index = i;
    out.floor_keypoint_error = floors[k];
    out.wrist_to_middle_mcp_px = WristToMiddleMcp(view.truth.keypoints);
    out.basic = view.basic;
    out.shape_name = view.shape_name;
    std::vector<CorrectnessJudge> judges;
    std::vector<bool> applies(num_criteria);
    for (size_t c = 0; c < num_criteria; ++c) {
      applies[c] = !criteria[c].basic_only || view.basic;
      judges.emplace_back(view.truth, view.basic, testset.axes, criteria[c].options);
    }
    out.ranks.assign(num_criteria, kNotApplicable);
    for (size_t c = 0; c < num_criteria; ++c) {
      if (applies[c]) out.ranks[c] = kNoCorrectMatch;
    }

    std::vector<int64_t> correct_pairs(num_criteria, 0);
    for (size_t c = 0; c < num_criteria; ++c) {
      if (applies[c]) correct_pairs[c] = CountCorrect(db_poses, db.num_rolls(), judges[c]);
    }
    out.num_correct = correct_pairs[0];
    out.correct_pairs = correct_pairs;
    const auto t_input = std::chrono::steady_clock::now();
    auto query = query_points(view);
    out.input_seconds = SecondsSince(t_input);
    if (!query.ok()) {
      out.error = query.status().message();
      outcomes.push_back(std::move(out));
      progress.Add();
      continue;
    }
    auto search = [&](const SearchOptions& o) {
      return query->picture ? SearchEvidence(searcher, *query->picture, o, options.landmark_rank)
                            : searcher.Search(query->points, o);
    };
    out.num_query_points = query->points.size();
    const auto t_search = std::chrono::steady_clock::now();
    auto matches = search(first);
    out.search_seconds = SecondsSince(t_search);
    if (!matches.ok()) {
      out.error = matches.status().message();
      outcomes.push_back(std::move(out));
      progress.Add();
      continue;
    }

    auto rank_all = [&](const std::vector<Match>& list) {
      bool missing = false;
      std::vector<PoseForEval> poses;
      poses.reserve(list.size());
      for (const Match& m : list) poses.push_back(PoseFromLabel(m.label, 0.0f));
      for (size_t c = 0; c < num_criteria; ++c) {
        if (!applies[c]) continue;
        out.ranks[c] = kNoCorrectMatch;
        for (size_t r = 0; r < poses.size(); ++r) {
          if (judges[c].IsCorrect(poses[r])) {
            out.ranks[c] = static_cast<int64_t>(r) + 1;
            break;
          }
        }
        // Worth a deeper search only if a correct pair exists beyond this list.
        missing = missing || (out.ranks[c] == kNoCorrectMatch && correct_pairs[c] > 0);
      }
      return missing;
    };
    const bool missing = rank_all(*matches);
    if (missing && deep.top_k > first.top_k) {
      auto deeper = search(deep);
      if (deeper.ok()) {
        rank_all(*deeper);
        out.deep_search = true;
      }
    }
    if (!matches->empty()) {
      const Match& best = matches->front();
      const PoseForEval pose = PoseFromLabel(best.label, 0.0f);
      out.top1 = MatchBrief{
          best.view_id, best.roll, best.distance, best.shape_name, judges[0].Judge(pose)};
      out.top1_keypoint_error = KeypointError(view.truth.keypoints, pose.keypoints);
      double best10 = std::numeric_limits<double>::infinity();
      for (size_t r = 0; r < std::min<size_t>(10, matches->size()); ++r) {
        best10 =
            std::min(best10, KeypointError(view.truth.keypoints, (*matches)[r].label.keypoints));
      }
      out.best10_keypoint_error = best10;
      if (options.fit_rig != nullptr && query->picture) {
        auto fit = FitPictureMatches(
            *options.fit_rig, searcher.database(), *query->picture, *matches, options.fit);
        if (!fit.ok()) return fit.status();
        out.fitted_keypoint_error = out.top1_keypoint_error;
        if (fit->best >= 0) {
          std::array<std::array<float, 3>, kNumKeypoints> kps{};
          const auto& fitted = fit->fits[fit->best].keypoints_3d;
          for (int j = 0; j < kNumKeypoints; ++j) {
            for (int c = 0; c < 3; ++c) kps[j][c] = static_cast<float>(fitted[j][c]);
          }
          out.fitted_keypoint_error = KeypointError(view.truth.keypoints, kps);
        }
      }
    }
    out.query_points = std::move(query->points);
    outcomes.push_back(std::move(out));
    progress.Add();
  }
  progress.Finish();
  return outcomes;
}

void FinishReport(EvaluationReport* report_ptr) {
  EvaluationReport& report = *report_ptr;
  const EvaluationOptions& options = report.options;
  std::stable_sort(
      report.views.begin(), report.views.end(), [](const ViewOutcome& a, const ViewOutcome& b) {
        return a.testset_index < b.testset_index;
      });
  report.tables.clear();
  report.views_without_correct.clear();
  report.success.clear();
  report.chance_success.clear();
  report.mean_correct_per_view = 0;
  report.failed_inputs = 0;
  report.deep_searches = 0;
  report.search_seconds = 0;
  report.input_seconds = 0;
  for (const auto& v : report.views) {
    if (!v.error.empty()) ++report.failed_inputs;
    if (v.deep_search) ++report.deep_searches;
    report.search_seconds += v.search_seconds;
    report.input_seconds += v.input_seconds;
  }

  // Tables and success per criterion, over the views each applies to.
  for (size_t c = 0; c < report.criteria.size(); ++c) {
    std::vector<int64_t> ranks;
    for (const auto& v : report.views) {
      if (v.ranks[c] != kNotApplicable) ranks.push_back(v.ranks[c]);
    }
    report.tables.push_back(MakeRankTable(ranks));
    int64_t without = 0;
    for (const auto& v : report.views) {
      if (v.ranks[c] != kNotApplicable && v.correct_pairs[c] == 0) ++without;
    }
    report.views_without_correct.push_back(without);
    for (int64_t n_top : options.success_n) {
      SuccessCell cell;
      cell.criterion = report.criteria[c].name;
      cell.d_deg = report.criteria[c].options.same_shape
                       ? 0
                       : report.criteria[c].options.max_joint_distance_deg;
      cell.n = n_top;
      cell.rate = SuccessAtN(ranks, n_top);
      cell.views = static_cast<int64_t>(ranks.size());
      report.success.push_back(cell);
    }
  }
  // Each error also in wrist-to-middle-knuckle lengths of its truth (NaN stays NaN).
  std::array<std::vector<double>, 4> hs;
  std::array<std::vector<double>, 4> wm;
  for (const auto& v : report.views) {
    const std::array<double, 4> e = {v.top1_keypoint_error,
                                     v.best10_keypoint_error,
                                     v.floor_keypoint_error,
                                     v.fitted_keypoint_error};
    for (size_t k = 0; k < e.size(); ++k) {
      hs[k].push_back(e[k]);
      wm[k].push_back(e[k] * kNormalisedDiameter / v.wrist_to_middle_mcp_px);
    }
  }
  if (!report.views.empty()) {
    double correct_sum = 0;
    for (int64_t n_top : options.success_n) {
      double sum = 0;
      for (const auto& v : report.views) {
        sum += ChanceOfCorrectInTopN(report.database_virtual_views,
                                     static_cast<uint64_t>(v.num_correct),
                                     static_cast<uint64_t>(n_top));
      }
      report.chance_success.push_back(sum / static_cast<double>(report.views.size()));
    }
    for (const auto& v : report.views) correct_sum += static_cast<double>(v.num_correct);
    report.mean_correct_per_view = correct_sum / static_cast<double>(report.views.size());
  }
  report.top1_keypoint_error = Summarise(hs[0]);
  report.best10_keypoint_error = Summarise(hs[1]);
  report.floor_keypoint_error = Summarise(hs[2]);
  report.fitted_keypoint_error = Summarise(hs[3]);
  report.top1_keypoint_error_wm = Summarise(wm[0]);
  report.best10_keypoint_error_wm = Summarise(wm[1]);
  report.floor_keypoint_error_wm = Summarise(wm[2]);
  report.fitted_keypoint_error_wm = Summarise(wm[3]);
  const double searched = static_cast<double>(report.views.size());
  report.queries_per_second = report.search_seconds > 0 ? searched / report.search_seconds : 0;
  const double e2e = report.search_seconds + report.input_seconds;
  report.end_to_end_queries_per_second = e2e > 0 ? searched / e2e : 0;
}

Result<EvaluationReport> Evaluate(const Searcher& searcher,
                                  const TestSet& testset,
                                  QueryInput input,
                                  const QueryPointsFn& query_points,
                                  const EvaluationOptions& options) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument, "evaluation options are invalid (see above)");
  }
  const auto wall_start = std::chrono::steady_clock::now();
  EvaluationReport report = StartReport(searcher.database(), testset, input, options);
  const std::vector<uint32_t> selected = SelectTestViews(testset, options);
  auto views = EvaluateViews(searcher, testset, query_points, options, selected);
  if (!views.ok()) return views.status();
  report.views = std::move(*views);
  FinishReport(&report);
  report.wall_seconds = SecondsSince(wall_start);
  return report;
}

namespace {
// The keypoint summaries in both units; the floor and the fitted pose only when measured.
nlohmann::json KeypointErrorsToJson(const EvaluationReport& report) {
  auto block = [](const char* units,
                  const Summary& top1,
                  const Summary& best10,
                  const Summary& floor,
                  const Summary& fitted) {
    nlohmann::json j = {
        {"units", units}, {"top1", SummaryToJson(top1)}, {"best_of_top10", SummaryToJson(best10)}};
    if (floor.count > 0) j["floor"] = SummaryToJson(floor);
    if (fitted.count > 0) j["fitted"] = SummaryToJson(fitted);
    return j;
  };
  nlohmann::json j =
      block("mean root-relative 3D keypoint distance / normalised hand diameter (192 px)",
            report.top1_keypoint_error,
            report.best10_keypoint_error,
            report.floor_keypoint_error,
            report.fitted_keypoint_error);
  j["wrist_to_middle_mcp"] =
      block("mean root-relative 3D keypoint distance / the truth's wrist-to-middle-MCP distance",
            report.top1_keypoint_error_wm,
            report.best10_keypoint_error_wm,
            report.floor_keypoint_error_wm,
            report.fitted_keypoint_error_wm);
  return j;
}
}  // namespace

nlohmann::json ReportToJson(const EvaluationReport& report) {
  nlohmann::json criteria = nlohmann::json::array();
  nlohmann::json tables = nlohmann::json::array();
  for (size_t c = 0; c < report.criteria.size(); ++c) {
    criteria.push_back(CriterionToJson(report.criteria[c]));
    nlohmann::json t = TableToJson(report.tables[c]);
    t["criterion"] = report.criteria[c].name;
    t["no_correct_in_database"] = report.views_without_correct[c];
    tables.push_back(t);
  }
  nlohmann::json success = nlohmann::json::array();
  for (const auto& s : report.success) {
    success.push_back({{"criterion", s.criterion},
                       {"d_deg", s.d_deg},
                       {"n", s.n},
                       {"rate", s.rate},
                       {"views", s.views}});
  }
  nlohmann::json views = nlohmann::json::array();
  for (const auto& v : report.views) {
    nlohmann::json j = {{"id", v.test_id},
                        {"basic", v.basic},
                        {"shape_name", v.shape_name},
                        {"ranks", v.ranks},
                        {"top1_keypoint_error", NumberOrNull(v.top1_keypoint_error)},
                        {"best10_keypoint_error", NumberOrNull(v.best10_keypoint_error)},
                        {"input_seconds", v.input_seconds},
                        {"search_seconds", v.search_seconds},
                        {"deep_search", v.deep_search},
                        {"query_points", v.num_query_points},
                        {"num_correct", v.num_correct},
                        {"wrist_to_middle_mcp_px", NumberOrNull(v.wrist_to_middle_mcp_px)}};
    if (!std::isnan(v.floor_keypoint_error)) j["floor_keypoint_error"] = v.floor_keypoint_error;
    if (!std::isnan(v.fitted_keypoint_error)) j["fitted_keypoint_error"] = v.fitted_keypoint_error;
    if (!v.error.empty()) j["error"] = v.error;
    if (v.top1) {
      j["top1"] = {{"view_id", v.top1->view_id},
                   {"roll", v.top1->roll},
                   {"distance", v.top1->distance},
                   {"shape_name", v.top1->shape_name},
                   {"joint_distance_deg", v.top1->detail.joint_distance_deg},
                   {"direction_deg", v.top1->detail.direction_deg},
                   {"roll_deg", v.top1->detail.roll_deg},
                   {"correct", v.top1->detail.correct()}};
    }
    views.push_back(std::move(j));
  }
  return {
      {"format", "handdb-evaluation"},
      {"version", 1},
      {"database",
       {{"path", report.database},
        {"views", report.database_views},
        {"rolls", report.database_rolls},
        {"virtual_views", report.database_virtual_views}}},
      {"testset",
       {{"path", report.testset}, {"seed", report.testset_seed}, {"views", report.views.size()}}},
      {"input", QueryInputName(report.input)},
      {"search",
       {{"first_k", report.options.first_k},
        {"max_rank", report.options.max_rank},
        {"threads", report.threads}}},
      {"criteria", criteria},
      {"rank_tables", tables},
      {"success", success},
      {"keypoint_error", KeypointErrorsToJson(report)},
      {"timing",
       {{"queries", report.views.size()},
        {"search_seconds", report.search_seconds},
        {"input_seconds", report.input_seconds},
        {"wall_seconds", report.wall_seconds},
        {"queries_per_second", report.queries_per_second},
        {"end_to_end_queries_per_second", report.end_to_end_queries_per_second},
        {"deep_searches", report.deep_searches}}},
      {"failed_inputs", report.failed_inputs},
      {"chance", ChanceToJson(report)},
      {"views", views},
  };
}

std::string ReportToText(const EvaluationReport& report) {
  std::ostringstream os;
  os << "database  " << report.database << ": " << report.database_views << " views x "
     << report.database_rolls << " rolls = " << report.database_virtual_views << " virtual views\n";
  os << "test set  " << report.testset << ": " << report.views.size() << " views (seed "
     << report.testset_seed << "), input " << QueryInputName(report.input);
  if (report.failed_inputs > 0) os << ", " << report.failed_inputs << " without a usable query";
  os << "\n";
  const Criterion& main = report.criteria[0];
  os << "correct   joint distance (" << JointDistanceKindName(main.options.joint_distance)
     << ") <= " << main.options.max_joint_distance_deg << " deg"
     << (main.options.same_shape ? " (same shape for basic-shape views)" : "")
     << ", view direction <= " << main.options.max_direction_deg
     << " deg, roll <= " << main.options.max_roll_deg << " deg ("
     << (main.options.roll_compare == RollCompare::kAligned ? "aligned" : "label") << ")\n\n";
  os << "Table 1: rank of the highest-ranking correct match\n";
  os << "  criterion  ";
  for (int b = 0; b < kNumRankBins; ++b) os << "  " << RankBinName(b);
  os << "  | views  none in DB\n";
  for (size_t c = 0; c < report.criteria.size(); ++c) {
    if (c > 1) break;  // the d grid is summarised by success@(d, n) below
    char line[256];
    std::snprintf(line, sizeof line, "  %-11s", report.criteria[c].name.c_str());
    os << line;
    for (int b = 0; b < kNumRankBins; ++b) {
      const std::string name(RankBinName(b));
      std::snprintf(line,
                    sizeof line,
                    "  %*lld",
                    static_cast<int>(name.size()),
                    static_cast<long long>(report.tables[c].counts[b]));
      os << line;
    }
    std::snprintf(line,
                  sizeof line,
                  "  | %5lld  %10lld\n",
                  static_cast<long long>(report.tables[c].total()),
                  static_cast<long long>(report.views_without_correct[c]));
    os << line;
  }
  os << "\nsuccess@(d, n) (share of views with a correct match in the top n)\n";
  os << "  criterion  ";
  for (int64_t n : report.options.success_n)
    os << FormatDouble("   n=%-4.0f", static_cast<double>(n));
  os << "\n";
  for (size_t c = 0; c < report.criteria.size(); ++c) {
    char line[64];
    std::snprintf(line, sizeof line, "  %-10s", report.criteria[c].name.c_str());
    os << line;
    for (const auto& s : report.success) {
      if (s.criterion == report.criteria[c].name) os << FormatDouble("  %6.1f%%", 100.0 * s.rate);
    }
    os << "\n";
  }
  if (!report.chance_success.empty()) {
    os << "  chance    ";
    for (double rate : report.chance_success) os << FormatDouble("  %6.2f%%", 100.0 * rate);
    os << FormatDouble("   (random ordering; %.1f correct (view, roll) per test view)\n",
                       report.mean_correct_per_view);
  }
  {
    char head[256];
    std::snprintf(head,
                  sizeof head,
                  "\n%-46s%-26s%s\n%46s%6s  %6s  %6s    %6s  %6s  %6s\n",
                  "3D keypoint error (root-relative)",
                  "in hand sizes (192 px)",
                  "in wrist-to-middle-MCP lengths",
                  "",
                  "median",
                  "mean",
                  "p90",
                  "median",
                  "mean",
                  "p90");
    os << head;
  }
  auto row = [&](const char* name, const Summary& hs, const Summary& wm) {
    char line[96];
    std::snprintf(line, sizeof line, "  %-44s", name);
    os << line << FormatDouble("%6.3f", hs.median) << FormatDouble("  %6.3f", hs.mean)
       << FormatDouble("  %6.3f", hs.p90) << FormatDouble("    %6.3f", wm.median)
       << FormatDouble("  %6.3f", wm.mean) << FormatDouble("  %6.3f\n", wm.p90);
  };
  row("top-1", report.top1_keypoint_error, report.top1_keypoint_error_wm);
  row("best of top 10", report.best10_keypoint_error, report.best10_keypoint_error_wm);
  if (report.fitted_keypoint_error.count > 0) {
    row("fitted pose", report.fitted_keypoint_error, report.fitted_keypoint_error_wm);
  }
  if (report.floor_keypoint_error.count > 0) {
    row("floor (best view and roll of the database)",
        report.floor_keypoint_error,
        report.floor_keypoint_error_wm);
  }
  os << "\n"
     << FormatDouble("speed     %.2f queries/s", report.queries_per_second) << " (search, top "
     << report.options.first_k << ", " << report.threads << " threads); "
     << FormatDouble("%.2f queries/s end to end", report.end_to_end_queries_per_second) << "; "
     << report.deep_searches << " deeper searches for ranks\n";
  return os.str();
}

Status WriteReportPlots(const EvaluationReport& report,
                        const Searcher& searcher,
                        const TestSet& testset,
                        const fs::path& dir,
                        const QueryPointsFn& query_points) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status(StatusCode::kIoError, dir.string() + ": " + ec.message());
  const std::string input = QueryInputName(report.input);
  HANDDB_RETURN_IF_ERROR(WriteRankHistogramPng(
      dir / "rank_histogram.png",
      report.tables[0],
      "Table 1 (" + input + " input, d = " +
          FormatDouble("%g", report.criteria[0].options.max_joint_distance_deg) + " deg)"));
  if (report.tables.size() > 1 && report.tables[1].total() > 0) {
    HANDDB_RETURN_IF_ERROR(
        WriteRankHistogramPng(dir / "rank_histogram_same_shape.png",
                              report.tables[1],
                              "Table 1, basic-shape views, same shape (" + input + " input)"));
  }
  std::vector<double> top1;
  std::vector<double> best10;
  std::vector<double> floors;
  for (const auto& v : report.views) {
    top1.push_back(v.top1_keypoint_error);
    best10.push_back(v.best10_keypoint_error);
    floors.push_back(v.floor_keypoint_error);
  }
  std::vector<CdfSeries> cdfs = {{"top-1", top1, {200, 90, 20}},
                                 {"best of top 10", best10, {40, 40, 220}}};
  if (report.floor_keypoint_error.count > 0) {
    cdfs.push_back({"floor (whole database)", floors, {40, 160, 40}});
  }
  HANDDB_RETURN_IF_ERROR(WriteCdfPng(dir / "keypoint_error_cdf.png",
                                     cdfs,
                                     "3D keypoint error CDF (" + input + " input)",
                                     "mean root-relative keypoint error / hand size",
                                     0));

  // Successes: rank 1 with the smallest keypoint error; failures: the worst ranks.
  const Database& db = searcher.database();
  auto tile_for = [&](const ViewOutcome& v) {
    ExampleTile tile;
    const int64_t rank = v.ranks[0];
    std::string rank_text = std::to_string(rank);
    if (v.num_correct == 0) {
      rank_text = "- (no correct view in the database)";
    } else if (rank == kNoCorrectMatch) {
      rank_text = ">" + std::to_string(report.options.max_rank);
    }
    tile.caption = "test " + std::to_string(v.test_id) + " " + v.shape_name + "  rank " + rank_text;
    tile.query_points = v.query_points;
    if (tile.query_points.empty() && v.error.empty() && query_points &&
        v.testset_index < testset.views.size()) {
      auto query = query_points(testset.views[v.testset_index]);
      if (query.ok()) tile.query_points = std::move(query->points);
    }
    if (v.top1) {
      tile.caption2 = "top-1 " + v.top1->shape_name +
                      FormatDouble("  kp %.3f", v.top1_keypoint_error) +
                      FormatDouble("  dir %.0f", v.top1->detail.direction_deg) +
                      FormatDouble("  roll %.0f", v.top1->detail.roll_deg) +
                      FormatDouble("  joints %.0f deg", v.top1->detail.joint_distance_deg);
      RollPoints(
          db.points(v.top1->view_id), RollAngle(v.top1->roll, db.num_rolls()), &tile.match_points);
    } else {
      tile.caption2 = v.error;
    }
    for (const auto& t : testset.views) {
      if (t.id == v.test_id) tile.image = t.photo;
    }
    return tile;
  };
  std::vector<const ViewOutcome*> ok;
  std::vector<const ViewOutcome*> bad;
  for (const auto& v : report.views) {
    if (v.ranks[0] == 1) {
      ok.push_back(&v);
    } else {
      bad.push_back(&v);
    }
  }
  std::sort(ok.begin(), ok.end(), [](const ViewOutcome* a, const ViewOutcome* b) {
    return a->top1_keypoint_error < b->top1_keypoint_error;
  });
  // Worst ranks first among views that have a correct pair in the database; views without any
  // (nothing to find) come last.
  auto badness = [](const ViewOutcome* v) {
    if (v->num_correct == 0) return int64_t{-1};
    return v->ranks[0] == kNoCorrectMatch ? std::numeric_limits<int64_t>::max() : v->ranks[0];
  };
  std::stable_sort(bad.begin(), bad.end(), [&](const ViewOutcome* a, const ViewOutcome* b) {
    return badness(a) > badness(b);
  });
  std::vector<ExampleTile> tiles;
  for (size_t i = 0; i < std::min<size_t>(6, ok.size()); ++i) tiles.push_back(tile_for(*ok[i]));
  HANDDB_RETURN_IF_ERROR(WriteExampleSheetPng(
      dir / "successes.png",
      tiles,
      "Successes (" + input + "): query edges blue, top-1 match red; correct at rank 1"));
  tiles.clear();
  for (size_t i = 0; i < std::min<size_t>(6, bad.size()); ++i) tiles.push_back(tile_for(*bad[i]));
  return WriteExampleSheetPng(
      dir / "failures.png",
      tiles,
      "Failures (" + input +
          "): query edges blue, top-1 match red; the worst ranks of a correct match");
}

}  // namespace handdb
