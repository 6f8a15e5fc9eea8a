// libFuzzer target for the test-set ground-truth reader (scripts/fuzz.sh): the bytes as
// DIR/testset.json through ReadTestSet (ReadJsonFile's bounds and schema, then the per-view
// fields), and through ReadSequenceTestSet (the frames of test sequences). Seeds: a two-view test
// set and the config corpus' 70-deep array.
#include <cmath>
#include <cstdint>
#include <cstdlib>

#include "evaluate/evaluate.h"
#include "evaluate/sequence.h"
#include "fuzz_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = handdb::fuzz::WriteInput(data, size, "testset.json");
  auto set = handdb::ReadTestSet(path);
  if (set.ok()) {
    // Whatever is accepted holds finite numbers only (the evaluation does arithmetic on them).
    for (const handdb::TestView& v : set->views) {
      for (float a : v.truth.joint_angles) {
        if (!std::isfinite(a)) std::abort();
      }
      for (const auto& kp : v.truth.keypoints) {
        for (float c : kp) {
          if (!std::isfinite(c)) std::abort();
        }
      }
    }
  }
  auto sequences = handdb::ReadSequenceTestSet(path);
  if (sequences.ok()) {
    for (const handdb::SequenceTruth& s : sequences->sequences) {
      for (const handdb::SequenceFrameTruth& f : s.frames) {
        for (const handdb::Point2f& p : f.keypoints_px) {
          if (!std::isfinite(p.x) || !std::isfinite(p.y)) std::abort();
        }
      }
    }
  }
  return 0;
}
