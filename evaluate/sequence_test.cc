#include "evaluate/sequence.h"

#include <gtest/gtest.h>

#include <cmath>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

// A hand of 21 keypoints spread over a 100 px box, in the normalised frame and the frame's px.
Keypoints BaseKeypoints() {
  Keypoints k{};
  for (int j = 0; j < kNumKeypoints; ++j) {
    k[j] = {static_cast<float>(5 * j), static_cast<float>((j % 5) * 20), static_cast<float>(j)};
  }
  return k;
}

SequenceFrameTruth Frame(uint32_t t, int in_picture, float dx = 0) {
  SequenceFrameTruth f;
  f.frame = t;
  f.time = t / 30.0;
  f.in_picture = in_picture;
  f.visible = in_picture == kNumKeypoints;
  f.keypoints = BaseKeypoints();
  for (int j = 0; j < kNumKeypoints; ++j) {
    f.keypoints_px[j] = {f.keypoints[j][0] + 50 + dx, f.keypoints[j][1] + 50};
  }
  return f;
}

FramePrediction Exact(const SequenceFrameTruth& f) {
  FramePrediction p;
  p.found = true;
  p.keypoints = f.keypoints;
  p.keypoints_px = f.keypoints_px;
  return p;
}

TEST(SequenceScore, ExactPredictionsHaveNoErrorAndTheTruthsJitter) {
  SequenceTruth truth;
  // The hand moves right with a constant acceleration of 2 px/frame^2.
  for (uint32_t t = 0; t < 6; ++t) truth.frames.push_back(Frame(t, 21, static_cast<float>(t * t)));
  std::vector<FramePrediction> p;
  for (const auto& f : truth.frames) p.push_back(Exact(f));
  const SequenceOutcome out =
      ScoreSequence(truth, p, std::vector<double>(6, 0.5), SequenceScoreOptions());
  EXPECT_EQ(out.stats.frames, 6);
  EXPECT_EQ(out.stats.found_visible, 6);
  EXPECT_NEAR(out.stats.error_3d.mean, 0, 1e-12);
  EXPECT_NEAR(out.stats.error_2d_px.mean, 0, 1e-6);
  EXPECT_EQ(out.stats.jitter_triples, 4);
  EXPECT_NEAR(out.stats.jitter_2d_px, 2.0, 1e-5);
  EXPECT_NEAR(out.stats.jitter_2d_px_truth, 2.0, 1e-5);
  EXPECT_NEAR(out.stats.jitter_3d, 0, 1e-12);  // root-relative: a translation does not jitter
  EXPECT_NEAR(out.stats.frames_per_second, 2.0, 1e-12);
  EXPECT_EQ(out.stats.returns, 0);
}

TEST(SequenceScore, JitterOfAnAlternatingPrediction) {
  SequenceTruth truth;
  for (uint32_t t = 0; t < 5; ++t) truth.frames.push_back(Frame(t, 21));
  std::vector<FramePrediction> p;
  for (uint32_t t = 0; t < 5; ++t) {
    FramePrediction q = Exact(truth.frames[t]);
    // Every other frame shifted 3 px right in the picture and the fingertip (keypoint 20) moved
    // 19.2 normalised px (0.1 hand sizes) in depth: second differences of 6 px and 0.2 hs.
    if (t % 2 == 1) {
      for (auto& k : q.keypoints_px) k.x += 3;
      q.keypoints[20][2] += 19.2f;
    }
    p.push_back(q);
  }
  const SequenceOutcome out =
      ScoreSequence(truth, p, std::vector<double>(5, 0.1), SequenceScoreOptions());
  EXPECT_EQ(out.stats.jitter_triples, 3);
  EXPECT_NEAR(out.stats.jitter_2d_px, 6.0, 1e-5);
  EXPECT_NEAR(out.stats.jitter_2d_px_truth, 0.0, 1e-9);
  EXPECT_NEAR(out.stats.jitter_3d, 0.2 / 20, 1e-6);  // one of the 20 root-relative keypoints
  // The 2D error: 3 px on frames 1 and 3, 0 elsewhere.
  EXPECT_NEAR(out.stats.error_2d_px.mean, 6.0 / 5, 1e-5);
  EXPECT_NEAR(out.frames[1].error_3d, 19.2 / 20 / kNormalisedDiameter, 1e-6);
}

TEST(SequenceScore, JitterSkipsFramesNotFoundOrNotVisible) {
  SequenceTruth truth;
  for (uint32_t t = 0; t < 7; ++t) truth.frames.push_back(Frame(t, t == 3 ? 10 : 21));
  std::vector<FramePrediction> p;
  for (const auto& f : truth.frames) p.push_back(Exact(f));
  p[5].found = false;
  const SequenceOutcome out =
      ScoreSequence(truth, p, std::vector<double>(7, 0.1), SequenceScoreOptions());
  // Triples (0,1,2) only: 3 is partly out, 5 not found.
  EXPECT_EQ(out.stats.jitter_triples, 1);
  EXPECT_EQ(out.stats.visible, 6);
  EXPECT_EQ(out.stats.found_visible, 5);
  EXPECT_EQ(out.stats.returns, 0);  // partly out is not a leave
}

TEST(SequenceScore, RecoveryCountsReturnsAfterTheHandWasWhollyOut) {
  // in picture: 21 21 10 0 0 10 21 21 21 21 21 21 | 0 21 21 21 21 21 21
  const std::vector<int> in = {
      21, 21, 10, 0, 0, 10, 21, 21, 21, 21, 21, 21, 0, 21, 21, 21, 21, 21, 21};
  SequenceTruth truth;
  for (uint32_t t = 0; t < in.size(); ++t) truth.frames.push_back(Frame(t, in[t]));
  std::vector<FramePrediction> p;
  for (const auto& f : truth.frames) p.push_back(Exact(f));
  // First return at frame 6: found only from frame 10 (the 5th frame from the return): recovered.
  for (int t = 2; t < 10; ++t) p[t].found = false;
  // Second return at frame 13: found at 13..18 but wrong by 50 px until frame 18 (6th frame):
  // found again, not recovered.
  for (int t = 13; t < 18; ++t) {
    for (auto& k : p[t].keypoints_px) k.x += 50;
  }
  p[12].found = false;
  p[4].found = true;  // a false find while the hand is wholly out
  SequenceScoreOptions options;
  const SequenceOutcome out = ScoreSequence(truth, p, std::vector<double>(in.size(), 0.1), options);
  EXPECT_EQ(out.stats.returns, 2);
  EXPECT_EQ(out.stats.recovered, 1);
  EXPECT_EQ(out.stats.found_again, 2);
  EXPECT_EQ(out.stats.false_finds, 1);
  EXPECT_EQ(out.stats.absent, 3);

  // Recovery must be within 4 frames: the first return is then missed too.
  options.recovery_frames = 4;
  const SequenceOutcome strict =
      ScoreSequence(truth, p, std::vector<double>(in.size(), 0.1), options);
  EXPECT_EQ(strict.stats.recovered, 0);
  EXPECT_EQ(strict.stats.found_again, 1);
}

TEST(SequenceScore, OverallCombinesSequences) {
  SequenceTruth a;
  for (uint32_t t = 0; t < 4; ++t) a.frames.push_back(Frame(t, 21, static_cast<float>(t * t)));
  SequenceTruth b;
  b.id = 1;
  for (uint32_t t = 0; t < 3; ++t) b.frames.push_back(Frame(t, t == 1 ? 0 : 21));
  std::vector<FramePrediction> pa, pb;
  for (const auto& f : a.frames) pa.push_back(Exact(f));
  for (const auto& f : b.frames) pb.push_back(Exact(f));
  pb[1].found = false;
  const SequenceScoreOptions options;
  std::vector<SequenceOutcome> outcomes = {ScoreSequence(a, pa, {1, 1, 1, 1}, options),
                                           ScoreSequence(b, pb, {1, 1, 1}, options)};
  const SequenceStats all = CombineSequenceStats(outcomes, options);
  EXPECT_EQ(all.frames, 7);
  EXPECT_EQ(all.visible, 6);
  EXPECT_EQ(all.jitter_triples, 2);
  EXPECT_NEAR(all.jitter_2d_px, 2.0, 1e-5);
  EXPECT_EQ(all.returns, 1);
  EXPECT_EQ(all.recovered, 1);
  EXPECT_NEAR(all.frames_per_second, 1.0, 1e-12);

  SequenceReport report;
  report.predictor = "exact";
  report.sequences = outcomes;
  report.overall = all;
  const nlohmann::json doc = SequenceReportToJson(report);
  EXPECT_TRUE(ValidateJson(doc, "sequence_evaluation.schema.json", "report").ok());
  EXPECT_NE(SequenceReportToText(report).find("overall"), std::string::npos);
}

TEST(SequenceScoreOptions, Check) {
  SequenceScoreOptions o;
  EXPECT_TRUE(o.Check());
  o.recovery_frames = 0;
  EXPECT_FALSE(o.Check());
}

nlohmann::json TruthItem(uint32_t id, uint32_t sequence, uint32_t frame, bool visible) {
  nlohmann::json kps = nlohmann::json::array();
  nlohmann::json px = nlohmann::json::array();
  for (int j = 0; j < kNumKeypoints; ++j) {
    kps.push_back({j, j, 0});
    px.push_back({j + 10, j + 20});
  }
  return {{"id", id},
          {"unit", 0},
          {"basic", false},
          {"shape_name", "s"},
          {"joint_angles", std::vector<double>(20, 0.0)},
          {"view_direction", {0, 0, 1}},
          {"view_theta", 0},
          {"view_phi", 0},
          {"camera_roll", 0},
          {"keypoints", kps},
          {"normalisation", {{"centre_px", {1, 1}}, {"diameter_px", 2}, {"scale", 1}}},
          {"num_edge_points", 10},
          {"label", "units/u00000/r000000.exr"},
          {"sidecar", "units/u00000/r000000.json"},
          {"photo", "photos/u00000/r000000.png"},
          {"sequence",
           {{"id", sequence},
            {"frame", frame},
            {"time", frame / 30.0},
            {"clutter", sequence == 1},
            {"offset_px", {0, 0}},
            {"keypoints_px", px},
            {"in_picture", visible ? 21 : 0},
            {"visible", visible}}}};
}

nlohmann::json TruthDoc(const nlohmann::json& items) {
  return {{"format", "handdb-testset"},
          {"version", 1},
          {"name", "seq"},
          {"seed", 1},
          {"plan", "testset_plan.json"},
          {"hand_model", {{"path", "h.json"}, {"sha256", std::string(64, 'a')}}},
          {"forward_axis", {0, 0, -1}},
          {"palm_normal", {0, 1, 0}},
          {"resolution", 64},
          {"ortho_scale", 0.3},
          {"clutter", false},
          {"sequence", {{"fps", 25}}},
          {"handdb_version", "x"},
          {"items", items}};
}

TEST(SequenceTestSet, ReadsFramesInOrderAndRefusesGaps) {
  const fs::path dir = testing::TempDir("seq_truth");
  nlohmann::json items = {TruthItem(0, 0, 1, true),
                          TruthItem(1, 0, 0, true),
                          TruthItem(2, 1, 0, false),
                          TruthItem(3, 1, 1, true)};
  ASSERT_TRUE(ValidateJson(TruthDoc(items), "testset.schema.json", "doc").ok());
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "testset.json", TruthDoc(items)).ok());
  auto is = IsSequenceTestSet(dir);
  ASSERT_TRUE(is.ok());
  EXPECT_TRUE(*is);
  auto set = ReadSequenceTestSet(dir);
  ASSERT_TRUE(set.ok()) << set.status().ToString();
  EXPECT_DOUBLE_EQ(set->fps, 25);
  ASSERT_EQ(set->sequences.size(), 2u);
  EXPECT_EQ(set->sequences[0].frames[0].view_index, 1u);
  EXPECT_EQ(set->sequences[0].frames[1].view_index, 0u);
  EXPECT_TRUE(set->sequences[1].clutter);
  EXPECT_FALSE(set->sequences[1].frames[0].visible);
  EXPECT_FLOAT_EQ(set->sequences[0].frames[0].keypoints_px[3].y, 23.0f);

  nlohmann::json huge = items;
  huge[3]["sequence"]["keypoints_px"][4][1] = 1e300;  // no float holds it
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "testset.json", TruthDoc(huge)).ok());
  auto refused = ReadSequenceTestSet(dir);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kOutOfRange);
  EXPECT_NE(refused.status().message().find("items[3].sequence.keypoints_px[4]"), std::string::npos)
      << refused.status().message();

  items[0]["sequence"]["frame"] = 2;  // frame 1 of sequence 0 missing
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "testset.json", TruthDoc(items)).ok());
  auto bad = ReadSequenceTestSet(dir);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("sequence 0: frame 1 missing"), std::string::npos)
      << bad.status().message();

  // A test set without sequences is not one.
  nlohmann::json plain = TruthDoc(items);
  plain.erase("sequence");
  for (auto& item : plain["items"]) item.erase("sequence");
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "testset.json", plain).ok());
  is = IsSequenceTestSet(dir);
  ASSERT_TRUE(is.ok());
  EXPECT_FALSE(*is);
  EXPECT_EQ(ReadSequenceTestSet(dir).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace handdb
