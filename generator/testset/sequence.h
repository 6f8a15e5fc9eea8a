// Test sequences (docs/evaluation.md, "Sequences"): a test set whose items are the frames of a
// few short videos, each a hand moving between natural poses while the view turns, on a plain or
// cluttered background, and in some of them leaving the picture and coming back. Their truth and
// photos are those of any test set; `handdb evaluate` scores a tracker on them
// (evaluate/sequence.h).
//
// Sequence s draws everything from Rng(DeriveSeed(seed, kSequenceStream, s)), in this order: the
// start direction (uniform on the sphere), the turn axis (uniform among the directions
// perpendicular to it), the start roll (uniform), the roll's sense, the side the hand leaves to.
// Its keyposes are natural poses (generator/sampling/natural_pose.h) of the stream seeded with
// the same derived seed, one every `keyposes_every` frames; the joint angles between two keyposes
// follow the smoothstep 3u^2 - 2u^3 of the frame's place between them, so they stay within the
// limits and the hand slows into each keypose instead of jumping. The view direction turns about
// the fixed axis by `turn_deg_per_frame`, and the camera turns with it as a rigid body (its image
// axes carried by the same rotation), then rolls by `roll_deg_per_frame`: the camera moves
// smoothly even where the roll number of docs/conventions.md jumps (near the forward axis).
//
// A leave stretch moves the hand out of the picture and back: an image-plane shift of the photo
// (the label render, the ground truth's pose, stays centred) that grows with the smoothstep over
// `move_frames` frames to `distance` picture widths, stays there `out_frames` frames, and shrinks
// back over `move_frames` frames, along a direction drawn per sequence.
#pragma once

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "format/view.h"
#include "generator/sampling/natural_pose.h"

namespace handdb {

// Stream tag of a sequence's randomness (its start view, turn, leave side, keyposes).
constexpr uint64_t kSequenceStream = 0x5345515545000000ull;  // "SEQUE"

enum class SequenceBackgrounds { kPlain, kCluttered, kAlternate };

struct SequenceLeaveOptions {
  std::vector<uint32_t> sequences;  // the sequences with a leave stretch
  double start = 0.4;               // the stretch starts at this share of the frames
  uint32_t move_frames = 6;         // frames to move out (and again to move back in)
  uint32_t out_frames = 8;          // frames wholly out of the picture
  double distance = 1.25;           // the shift out, in picture widths
};

struct SequenceOptions {
  uint32_t sequences = 4;
  uint32_t frames = 60;  // per sequence
  double fps = 30;
  uint32_t keyposes_every = 20;     // frames between keyposes
  double turn_deg_per_frame = 1.0;  // the view direction's turn
  double roll_deg_per_frame = 0.5;  // the camera roll's turn
  // alternate: even sequences plain, odd ones cluttered.
  SequenceBackgrounds backgrounds = SequenceBackgrounds::kAlternate;
  SequenceLeaveOptions leave;
  bool Check() const;

  // The config's "sequence" object (schemas/testset_config.schema.json), defaults filled in; the
  // checks the schema cannot make (a leave stretch that does not fit its sequence, a leave of a
  // sequence that does not exist) are kInvalidArgument errors naming `what`.
  static Result<SequenceOptions> FromJson(const nlohmann::json& j, const std::string& what);
  // Every field, defaults included: the plan records it.
  nlohmann::json ToJson() const;
};

struct SequenceFrame {
  uint32_t sequence = 0;
  uint32_t frame = 0;
  double time = 0;  // seconds: frame / fps
  JointVector joints{};
  bool clamped = false;  // a keypose was clamped to the limits
  std::array<double, 3> direction{};
  double roll = 0;  // radians in [0, 2 pi)
  bool clutter = false;
  std::array<double, 2> photo_offset_px{};  // the hand's shift in the photo (x right, y down)
  bool leaving = false;                     // inside a leave stretch (shifted)
  uint64_t seed = 0;                        // the sequence's seed: the same background and lights
};

// The frames of every sequence, sequence by sequence, in frame order. `resolution` converts the
// leave distance to px; the hand model's axes give the roll of each frame's camera.
std::vector<SequenceFrame> PlanSequenceFrames(const SequenceOptions& options,
                                              const NaturalPoseOptions& natural,
                                              const JointLimits& limits,
                                              uint64_t seed,
                                              int resolution,
                                              const std::array<double, 3>& forward_axis,
                                              const std::array<double, 3>& palm_normal);

}  // namespace handdb
