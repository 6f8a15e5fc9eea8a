#include "evaluate/sequence.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>

#include "base/json_number.h"
#include "base/json_schema.h"
#include "base/progress.h"
#include "evaluate/photo_keypoints.h"

namespace handdb {
namespace fs = std::filesystem;
namespace {

fs::path TestSetFile(const fs::path& dir_or_file) {
  return fs::is_directory(dir_or_file) ? dir_or_file / "testset.json" : dir_or_file;
}

Status SequenceFieldError(const fs::path& file, const std::string& message) {
  return Status(StatusCode::kInvalidArgument, file.string() + ": " + message);
}

// Root-relative keypoints (the wrist at the origin), as KeypointError compares them.
std::array<std::array<double, 3>, kNumKeypoints> RootRelative(const Keypoints& k) {
  std::array<std::array<double, 3>, kNumKeypoints> out{};
  for (int j = 0; j < kNumKeypoints; ++j) {
    for (int c = 0; c < 3; ++c) out[j][c] = static_cast<double>(k[j][c]) - k[0][c];
  }
  return out;
}

// Mean over the 20 non-wrist keypoints of |a - 2 b + c| of root-relative 3D keypoints, in hand
// sizes (the unit of KeypointError).
double SecondDifference3d(const Keypoints& a, const Keypoints& b, const Keypoints& c) {
  const auto ra = RootRelative(a);
  const auto rb = RootRelative(b);
  const auto rc = RootRelative(c);
  double sum = 0;
  for (int j = 1; j < kNumKeypoints; ++j) {
    double sq = 0;
    for (int k = 0; k < 3; ++k) {
      const double d = ra[j][k] - 2 * rb[j][k] + rc[j][k];
      sq += d * d;
    }
    sum += std::sqrt(sq);
  }
  return sum / (kNumKeypoints - 1) / kNormalisedDiameter;
}

// Mean over the 21 keypoints of |a - 2 b + c| in the frame's px.
double SecondDifference2d(const std::array<Point2f, kNumKeypoints>& a,
                          const std::array<Point2f, kNumKeypoints>& b,
                          const std::array<Point2f, kNumKeypoints>& c) {
  double sum = 0;
  for (int j = 0; j < kNumKeypoints; ++j) {
    const double dx = static_cast<double>(a[j].x) - 2.0 * b[j].x + c[j].x;
    const double dy = static_cast<double>(a[j].y) - 2.0 * b[j].y + c[j].y;
    sum += std::hypot(dx, dy);
  }
  return sum / kNumKeypoints;
}

// The per-frame quantities a sequence's statistics are made of, so that the overall statistics
// are computed from all sequences' parts exactly as one sequence's are.
struct StatParts {
  std::vector<double> error_3d, error_3d_wm, error_2d_px, error_2d;
  double jitter_3d = 0, jitter_3d_truth = 0, jitter_2d = 0, jitter_2d_truth = 0;
  SequenceStats counts;
};

void AddSequenceParts(const SequenceTruth& truth,
                      const SequenceOutcome& outcome,
                      const std::vector<FramePrediction>* predictions,
                      const SequenceScoreOptions& options,
                      StatParts* parts) {
  SequenceStats& s = parts->counts;
  const auto& frames = outcome.frames;
  const size_t n = frames.size();
  for (size_t t = 0; t < n; ++t) {
    const FrameOutcome& f = frames[t];
    ++s.frames;
    s.seconds += f.seconds;
    if (f.visible) ++s.visible;
    if (f.in_picture == 0) ++s.absent;
    if (f.visible && f.found) {
      ++s.found_visible;
      parts->error_3d.push_back(f.error_3d);
      parts->error_3d_wm.push_back(f.error_3d_wm);
      parts->error_2d_px.push_back(f.error_2d_px);
      parts->error_2d.push_back(f.error_2d);
    }
    if (f.in_picture == 0 && f.found) ++s.false_finds;
  }
  // Jitter over triples of consecutive visible found frames.
  if (predictions != nullptr) {
    for (size_t t = 1; t + 1 < n; ++t) {
      bool ok = true;
      for (size_t u = t - 1; u <= t + 1; ++u) ok = ok && frames[u].visible && frames[u].found;
      if (!ok) continue;
      const auto& p = *predictions;
      const auto& tr = truth.frames;
      ++s.jitter_triples;
      parts->jitter_3d +=
          SecondDifference3d(p[t - 1].keypoints, p[t].keypoints, p[t + 1].keypoints);
      parts->jitter_3d_truth +=
          SecondDifference3d(tr[t - 1].keypoints, tr[t].keypoints, tr[t + 1].keypoints);
      parts->jitter_2d +=
          SecondDifference2d(p[t - 1].keypoints_px, p[t].keypoints_px, p[t + 1].keypoints_px);
      parts->jitter_2d_truth +=
          SecondDifference2d(tr[t - 1].keypoints_px, tr[t].keypoints_px, tr[t + 1].keypoints_px);
    }
  }
  // Returns: the first wholly visible frame after a stretch without one that had the hand
  // wholly out at least once, after the hand had been seen.
  bool seen = false;
  bool gone = false;  // since the last visible frame, a frame wholly out
  for (size_t t = 0; t < n; ++t) {
    if (!frames[t].visible) {
      gone = gone || (seen && frames[t].in_picture == 0);
      continue;
    }
    if (gone) {
      ++s.returns;
      bool found = false;
      bool recovered = false;
      const size_t end = std::min(n, t + static_cast<size_t>(options.recovery_frames));
      for (size_t u = t; u < end; ++u) {
        if (!frames[u].found) continue;
        found = true;
        if (frames[u].visible && frames[u].error_2d <= options.recovery_max_error) recovered = true;
      }
      s.found_again += found ? 1 : 0;
      s.recovered += recovered ? 1 : 0;
    }
    seen = true;
    gone = false;
  }
}

SequenceStats FinishParts(const StatParts& parts) {
  SequenceStats s = parts.counts;
  s.error_3d = Summarise(parts.error_3d);
  s.error_3d_wm = Summarise(parts.error_3d_wm);
  s.error_2d_px = Summarise(parts.error_2d_px);
  s.error_2d = Summarise(parts.error_2d);
  if (s.jitter_triples > 0) {
    const double n = static_cast<double>(s.jitter_triples);
    s.jitter_3d = parts.jitter_3d / n;
    s.jitter_3d_truth = parts.jitter_3d_truth / n;
    s.jitter_2d_px = parts.jitter_2d / n;
    s.jitter_2d_px_truth = parts.jitter_2d_truth / n;
  }
  s.frames_per_second = s.seconds > 0 ? static_cast<double>(s.frames) / s.seconds : 0;
  return s;
}

}  // namespace

Result<bool> IsSequenceTestSet(const fs::path& dir_or_file) {
  auto doc = ReadJsonFile(TestSetFile(dir_or_file), "");
  if (!doc.ok()) return doc.status();
  return doc->is_object() && doc->contains("sequence");
}

Result<SequenceTestSet> ReadSequenceTestSet(const fs::path& dir_or_file) {
  auto testset = ReadTestSet(dir_or_file);
  if (!testset.ok()) return testset.status();
  const fs::path file = testset->file;
  auto doc = ReadJsonFile(file, "testset.schema.json");
  if (!doc.ok()) return doc.status();
  if (!doc->contains("sequence")) {
    return SequenceFieldError(file, "not a sequence test set (no \"sequence\")");
  }
  SequenceTestSet out;
  out.fps = doc->at("sequence").value("fps", 30.0);
  const nlohmann::json& items = doc->at("items");
  std::map<uint32_t, SequenceTruth> by_id;
  for (size_t i = 0; i < items.size(); ++i) {
    const nlohmann::json& j = items[i];
    if (!j.contains("sequence")) {
      return SequenceFieldError(file, "items[" + std::to_string(i) + "] is not a sequence frame");
    }
    const nlohmann::json& sj = j.at("sequence");
    const std::string at = "items[" + std::to_string(i) + "].sequence.";
    // The schema fixed the types; the ranges are checked here, as ReadTestSet does.
    auto out_of_range = [&](const std::string& field, const nlohmann::json& value) {
      return Status(StatusCode::kOutOfRange,
                    file.string() + ": " + at + field + " is " + value.dump().substr(0, 40) +
                        ", outside its range");
    };
    SequenceFrameTruth f;
    f.view_index = static_cast<uint32_t>(i);
    for (const char* key : {"id", "frame"}) {
      if (sj.at(key).get<uint64_t>() > std::numeric_limits<uint32_t>::max()) {
        return out_of_range(key, sj.at(key));
      }
    }
    f.sequence = sj.at("id").get<uint32_t>();
    f.frame = sj.at("frame").get<uint32_t>();
    f.time = sj.at("time").get<double>();
    if (!std::isfinite(f.time)) return out_of_range("time", sj.at("time"));
    f.clutter = sj.at("clutter").get<bool>();
    f.in_picture = sj.at("in_picture").get<int>();
    f.visible = sj.at("visible").get<bool>();
    for (int k = 0; k < kNumKeypoints; ++k) {
      const nlohmann::json& p = sj.at("keypoints_px").at(k);
      for (int c = 0; c < 2; ++c) {
        const double v = p.at(c).get<double>();
        if (!std::isfinite(v) || std::abs(v) > std::numeric_limits<float>::max()) {
          return out_of_range("keypoints_px[" + std::to_string(k) + "]", p);
        }
      }
      f.keypoints_px[k] = {p.at(0).get<float>(), p.at(1).get<float>()};
    }
    f.keypoints = testset->views[i].truth.keypoints;
    f.photo = testset->views[i].photo;
    SequenceTruth& seq = by_id[f.sequence];
    seq.id = f.sequence;
    seq.clutter = f.clutter;
    seq.frames.push_back(f);
  }
  for (auto& [id, seq] : by_id) {
    std::sort(seq.frames.begin(), seq.frames.end(), [](const auto& a, const auto& b) {
      return a.frame < b.frame;
    });
    for (size_t k = 0; k < seq.frames.size(); ++k) {
      if (seq.frames[k].frame != k) {
        return SequenceFieldError(file,
                                  "sequence " + std::to_string(id) + ": frame " +
                                      std::to_string(k) + " missing or given twice");
      }
    }
    out.sequences.push_back(std::move(seq));
  }
  out.testset = std::move(testset).value();
  return out;
}

FramePredictor MakeFrameAlonePredictor(const Searcher& searcher, PictureSearchOptions options) {
  THROW_CHECK(options.Check());
  return [&searcher, options](const SequenceFrameInput& in) -> Result<FramePrediction> {
    FramePrediction p;
    auto result = SearchPicture(searcher, in.photo, options);
    if (!result.ok()) {
      if (result.status().code() == StatusCode::kNoHand) return p;
      return result.status();
    }
    if (result->matches.empty()) return p;
    p.found = true;
    const Match& top = result->matches.front();
    const PictureFit& fit = result->fit;
    if (fit.best == 0) {
      const MatchFit& mf = fit.fits[0];
      for (int j = 0; j < kNumKeypoints; ++j) {
        for (int c = 0; c < 3; ++c) p.keypoints[j][c] = static_cast<float>(mf.keypoints_3d[j][c]);
        p.keypoints_px[j] = mf.keypoints_image_px[j];
      }
      p.joint_angles = mf.fit.joints;
      return p;
    }
    const QueryEdges& edges = result->evidence.edges;
    for (int j = 0; j < kNumKeypoints; ++j) {
      p.keypoints[j] = top.label.keypoints[j];
      p.keypoints_px[j] =
          edges.ImageFromNormalised({top.label.keypoints[j][0], top.label.keypoints[j][1]});
    }
    for (int k = 0; k < kNumJointAngles; ++k) p.joint_angles[k] = top.label.joint_angles[k];
    return p;
  };
}

bool SequenceScoreOptions::Check() const {
  CHECK_OPTION_GE(recovery_frames, 1);
  CHECK_OPTION_GE(recovery_max_error, 0.0);
  CHECK_OPTION_GE(max_sequences, 0);
  return true;
}

SequenceOutcome ScoreSequence(const SequenceTruth& truth,
                              const std::vector<FramePrediction>& predictions,
                              const std::vector<double>& seconds,
                              const SequenceScoreOptions& options) {
  THROW_CHECK(options.Check());
  THROW_CHECK(predictions.size() == truth.frames.size());
  THROW_CHECK(seconds.size() == truth.frames.size());
  SequenceOutcome out;
  out.id = truth.id;
  out.clutter = truth.clutter;
  for (size_t t = 0; t < truth.frames.size(); ++t) {
    const SequenceFrameTruth& tr = truth.frames[t];
    const FramePrediction& p = predictions[t];
    FrameOutcome f;
    f.frame = tr.frame;
    f.visible = tr.visible;
    f.in_picture = tr.in_picture;
    f.found = p.found;
    f.seconds = seconds[t];
    if (tr.visible && p.found) {
      f.error_3d = KeypointError(tr.keypoints, p.keypoints);
      f.error_3d_wm = f.error_3d * kNormalisedDiameter / WristToMiddleMcp(tr.keypoints);
      PhotoKeypoints kp;
      kp.px = tr.keypoints_px;
      kp.visible.fill(true);
      kp.hand_size_px = HandSizePx(kp);
      const auto distances = KeypointDistancesPx(kp, p.keypoints_px);
      f.error_2d_px = MeanKeypointError(distances, 1.0);
      f.error_2d = MeanKeypointError(distances, kp.hand_size_px);
    }
    out.frames.push_back(f);
  }
  StatParts parts;
  AddSequenceParts(truth, out, &predictions, options, &parts);
  out.stats = FinishParts(parts);
  return out;
}

namespace {

// The jitter sums of a sequence, recovered from its finished means, so the overall jitter is
// the mean over every triple of every sequence.
void AddJitter(const SequenceStats& s, StatParts* parts) {
  if (s.jitter_triples == 0) return;
  const double n = static_cast<double>(s.jitter_triples);
  parts->jitter_3d += s.jitter_3d * n;
  parts->jitter_3d_truth += s.jitter_3d_truth * n;
  parts->jitter_2d += s.jitter_2d_px * n;
  parts->jitter_2d_truth += s.jitter_2d_px_truth * n;
  parts->counts.jitter_triples += s.jitter_triples;
}

}  // namespace

SequenceStats CombineSequenceStats(const std::vector<SequenceOutcome>& sequences,
                                   const SequenceScoreOptions& options) {
  StatParts parts;
  for (const SequenceOutcome& seq : sequences) {
    SequenceTruth no_truth;
    AddSequenceParts(no_truth, seq, nullptr, options, &parts);
    AddJitter(seq.stats, &parts);
  }
  return FinishParts(parts);
}

SequencePredictor FrameByFrame(FramePredictor predictor) {
  return [predictor = std::move(predictor)](
             const std::vector<SequenceFrameInput>& frames,
             double /*fps*/,
             std::vector<double>* seconds,
             const std::function<void()>& frame_done) -> Result<std::vector<FramePrediction>> {
    std::vector<FramePrediction> predictions;
    for (const SequenceFrameInput& in : frames) {
      const auto t0 = std::chrono::steady_clock::now();
      auto p = predictor(in);
      seconds->push_back(SecondsSince(t0));
      if (!p.ok()) return p.status();
      predictions.push_back(*p);
      frame_done();
    }
    return predictions;
  };
}

Result<SequenceReport> EvaluateSequences(const SequenceTestSet& testset,
                                         const FramePredictor& predictor,
                                         const SequenceScoreOptions& options) {
  return EvaluateSequences(testset, FrameByFrame(predictor), options);
}

Result<SequenceReport> EvaluateSequences(const SequenceTestSet& testset,
                                         const SequencePredictor& predictor,
                                         const SequenceScoreOptions& options) {
  if (!options.Check()) return Status(StatusCode::kInvalidArgument, "bad sequence options");
  const auto start = std::chrono::steady_clock::now();
  SequenceReport report;
  report.testset = testset.testset.dir.string();
  report.fps = testset.fps;
  report.options = options;
  size_t num_sequences = testset.sequences.size();
  if (options.max_sequences > 0) {
    num_sequences = std::min<size_t>(num_sequences, options.max_sequences);
  }
  uint64_t total = 0;
  for (size_t s = 0; s < num_sequences; ++s) total += testset.sequences[s].frames.size();
  Progress progress("sequence frames", total, options.progress, "frames");
  for (size_t s = 0; s < num_sequences; ++s) {
    const SequenceTruth& truth = testset.sequences[s];
    std::vector<SequenceFrameInput> inputs;
    for (size_t t = 0; t < truth.frames.size(); ++t) {
      const SequenceFrameTruth& f = truth.frames[t];
      if (f.photo.empty()) {
        return Status(StatusCode::kNotFound,
                      testset.testset.file.string() + ": sequence " + std::to_string(truth.id) +
                          " frame " + std::to_string(f.frame) +
                          ": no photo (the test set was made with --no-photos)");
      }
      SequenceFrameInput in;
      in.sequence = truth.id;
      in.frame = f.frame;
      in.time = f.time;
      in.first = t == 0;
      in.photo = f.photo;
      inputs.push_back(std::move(in));
    }
    std::vector<double> seconds;
    auto predictions = predictor(inputs, testset.fps, &seconds, [&] { progress.Add(); });
    if (!predictions.ok()) return predictions.status();
    THROW_CHECK_EQ(predictions->size(), inputs.size());
    THROW_CHECK_EQ(seconds.size(), inputs.size());
    report.sequences.push_back(ScoreSequence(truth, *predictions, seconds, options));
  }
  progress.Finish();
  report.overall = CombineSequenceStats(report.sequences, options);
  report.wall_seconds = SecondsSince(start);
  return report;
}

namespace {

nlohmann::json SequenceSummaryJson(const Summary& s) {
  if (s.count == 0) return {{"count", 0}};
  return {{"count", s.count}, {"mean", s.mean}, {"median", s.median}, {"p90", s.p90}};
}

nlohmann::json SequenceStatsJson(const SequenceStats& s) {
  return {
      {"frames", s.frames},
      {"visible_frames", s.visible},
      {"absent_frames", s.absent},
      {"found_visible", s.found_visible},
      {"false_finds", s.false_finds},
      {"keypoint_error",
       {{"hand_sizes", SequenceSummaryJson(s.error_3d)},
        {"wrist_to_middle_mcp", SequenceSummaryJson(s.error_3d_wm)}}},
      {"keypoint_error_2d",
       {{"px", SequenceSummaryJson(s.error_2d_px)},
        {"hand_sizes", SequenceSummaryJson(s.error_2d)}}},
      {"jitter",
       {{"triples", s.jitter_triples},
        {"keypoints_3d", NumberOrNull(s.jitter_3d)},
        {"keypoints_3d_truth", NumberOrNull(s.jitter_3d_truth)},
        {"keypoints_px", NumberOrNull(s.jitter_2d_px)},
        {"keypoints_px_truth", NumberOrNull(s.jitter_2d_px_truth)}}},
      {"recovery",
       {{"returns", s.returns},
        {"recovered", s.recovered},
        {"found_again", s.found_again},
        {"share",
         s.returns > 0 ? nlohmann::json(static_cast<double>(s.recovered) / s.returns)
                       : nlohmann::json(nullptr)}}},
      {"seconds", s.seconds},
      {"frames_per_second", s.frames_per_second},
  };
}

std::string Fixed(double v, int digits) {
  if (!std::isfinite(v)) return "-";
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

std::string StatsLine(const std::string& name, const SequenceStats& s) {
  char buf[512];
  const std::string recovery =
      s.returns > 0 ? std::to_string(s.recovered) + "/" + std::to_string(s.returns) : "-";
  std::snprintf(buf,
                sizeof buf,
                "%-9s %6lld %6lld %6lld  %6s %6s %6s %7s  %7s %7s %7s %7s  %9s %5lld %6s\n",
                name.c_str(),
                static_cast<long long>(s.frames),
                static_cast<long long>(s.visible),
                static_cast<long long>(s.found_visible),
                Fixed(s.error_3d.mean, 3).c_str(),
                Fixed(s.error_3d_wm.mean, 3).c_str(),
                Fixed(s.error_2d.mean, 3).c_str(),
                Fixed(s.error_2d_px.mean, 1).c_str(),
                Fixed(s.jitter_3d, 4).c_str(),
                Fixed(s.jitter_3d_truth, 4).c_str(),
                Fixed(s.jitter_2d_px, 2).c_str(),
                Fixed(s.jitter_2d_px_truth, 2).c_str(),
                recovery.c_str(),
                static_cast<long long>(s.false_finds),
                Fixed(s.frames_per_second, 2).c_str());
  return buf;
}

}  // namespace

nlohmann::json SequenceReportToJson(const SequenceReport& report) {
  nlohmann::json sequences = nlohmann::json::array();
  for (const SequenceOutcome& seq : report.sequences) {
    nlohmann::json frames = nlohmann::json::array();
    for (const FrameOutcome& f : seq.frames) {
      nlohmann::json j = {{"frame", f.frame},
                          {"visible", f.visible},
                          {"in_picture", f.in_picture},
                          {"found", f.found},
                          {"seconds", f.seconds}};
      if (std::isfinite(f.error_3d)) {
        j["keypoint_error"] = f.error_3d;
        j["keypoint_error_wm"] = f.error_3d_wm;
        j["keypoint_error_2d_px"] = f.error_2d_px;
        j["keypoint_error_2d"] = f.error_2d;
      }
      frames.push_back(std::move(j));
    }
    sequences.push_back({{"id", seq.id},
                         {"clutter", seq.clutter},
                         {"stats", SequenceStatsJson(seq.stats)},
                         {"frames", frames}});
  }
  return {{"format", "handdb-sequence-evaluation"},
          {"version", 1},
          {"database", report.database},
          {"testset", report.testset},
          {"predictor", report.predictor},
          {"fps", report.fps},
          {"options",
           {{"recovery_frames", report.options.recovery_frames},
            {"recovery_max_error", report.options.recovery_max_error},
            {"max_sequences", report.options.max_sequences}}},
          {"overall", SequenceStatsJson(report.overall)},
          {"sequences", sequences},
          {"wall_seconds", report.wall_seconds}};
}

std::string SequenceReportToText(const SequenceReport& report) {
  std::string out;
  out += "sequence evaluation: " + report.testset + " against " + report.database + "\n";
  out += "predictor: " + report.predictor + "; " + std::to_string(report.sequences.size()) +
         " sequences at " + Fixed(report.fps, 1) + " frames/s\n";
  out +=
      "errors over frames with the hand wholly in the picture and found; 3D root-relative in hand "
      "sizes (hs) and wrist-to-middle-MCP lengths (wm), 2D mean px and hand sizes (keypoint box "
      "diagonal); jitter = mean |k[t+1] - 2k[t] + k[t-1]| over consecutive found frames (3D hs, "
      "2D px; 'truth' the truth's own over the same frames); recovered = found within " +
      std::to_string(report.options.recovery_frames) +
      " frames of a return with 2D error <= " + Fixed(report.options.recovery_max_error, 2) +
      " hs\n\n";
  out +=
      "sequence  frames  shown  found  3D(hs) 3D(wm) 2D(hs)  2D(px)  jit3D  truth3D   jit2D "
      "truth2D  recovered false frames/s\n";
  for (const SequenceOutcome& seq : report.sequences) {
    out += StatsLine("s" + std::to_string(seq.id) + (seq.clutter ? " clut" : " plain"), seq.stats);
  }
  out += StatsLine("overall", report.overall);
  const SequenceStats& o = report.overall;
  if (o.returns > 0) {
    out += "returns: " + std::to_string(o.returns) + ", recovered " + std::to_string(o.recovered) +
           " (" + Fixed(100.0 * o.recovered / o.returns, 1) + "%), found at all " +
           std::to_string(o.found_again) + "\n";
  }
  out += "wall time " + Fixed(report.wall_seconds, 1) + " s\n";
  return out;
}

}  // namespace handdb
