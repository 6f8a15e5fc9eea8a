#include "generator/testset/sequence.h"

#include <algorithm>
#include <cmath>

#include "base/json_number.h"
#include "generator/hand/camera.h"
#include "generator/sampling/random.h"

namespace handdb {
namespace {

double Smoothstep(double u) {
  u = std::clamp(u, 0.0, 1.0);
  return u * u * (3.0 - 2.0 * u);
}

using Vec3 = std::array<double, 3>;

Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

Vec3 Normalised(const Vec3& v) {
  const double n = std::hypot(v[0], v[1], v[2]);
  return {v[0] / n, v[1] / n, v[2] / n};
}

double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// Rodrigues' rotation of v about the unit `axis` by `angle`.
Vec3 TurnAbout(const Vec3& v, const Vec3& axis, double angle) {
  const Vec3 w = Cross(axis, v);
  const double c = std::cos(angle);
  const double s = std::sin(angle);
  const double k = Dot(axis, v) * (1 - c);
  return Normalised({v[0] * c + w[0] * s + axis[0] * k,
                     v[1] * c + w[1] * s + axis[1] * k,
                     v[2] * c + w[2] * s + axis[2] * k});
}

// The roll whose camera (CamFromHandRotation) looking along `direction` has its image x axis
// nearest `x_axis` (a unit vector perpendicular to the direction).
double RollForCameraX(const Vec3& direction,
                      const Vec3& x_axis,
                      const Vec3& forward_axis,
                      const Vec3& palm_normal) {
  auto at0 = CamFromHandRotation(direction, forward_axis, palm_normal, 0.0);
  auto at90 = CamFromHandRotation(direction, forward_axis, palm_normal, M_PI / 2);
  THROW_CHECK_MSG(at0.ok() && at90.ok(), "sequence camera: " + at0.status().ToString());
  // Whichever way the roll turns the axes, x(a) = cos a x(0) + sense sin a y(0).
  const double sense = Dot((*at90)[0], (*at0)[1]) >= 0 ? 1.0 : -1.0;
  return std::atan2(sense * Dot(x_axis, (*at0)[1]), Dot(x_axis, (*at0)[0]));
}

// The shift out of the picture at frame f, as a share of the full distance.
double LeaveShare(const SequenceLeaveOptions& leave, uint32_t first, uint32_t f) {
  const double move = leave.move_frames;
  const int64_t i = static_cast<int64_t>(f) - first;
  const int64_t out_end = static_cast<int64_t>(leave.move_frames) + leave.out_frames;
  if (i <= 0) return 0;
  if (i < static_cast<int64_t>(leave.move_frames)) return Smoothstep(i / move);
  if (i < out_end) return 1;
  return Smoothstep(1.0 - static_cast<double>(i - out_end + 1) / move);
}

Status SequenceConfigError(const std::string& what, const std::string& message) {
  return Status(StatusCode::kInvalidArgument, what + ": sequence: " + message);
}

}  // namespace

bool SequenceOptions::Check() const {
  CHECK_OPTION_GE(sequences, 1u);
  CHECK_OPTION_GE(frames, 3u);
  CHECK_OPTION_GT(fps, 0.0);
  CHECK_OPTION_GE(keyposes_every, 1u);
  CHECK_OPTION_GE(turn_deg_per_frame, 0.0);
  CHECK_OPTION_GE(roll_deg_per_frame, 0.0);
  CHECK_OPTION_GE(leave.start, 0.0);
  CHECK_OPTION_LE(leave.start, 1.0);
  CHECK_OPTION_GE(leave.move_frames, 1u);
  CHECK_OPTION_GE(leave.out_frames, 1u);
  CHECK_OPTION_GT(leave.distance, 0.0);
  for (uint32_t s : leave.sequences) CHECK_OPTION_LT(s, sequences);
  return true;
}

Result<SequenceOptions> SequenceOptions::FromJson(const nlohmann::json& j,
                                                  const std::string& what) {
  SequenceOptions o;
  try {
    if (j.contains("sequences"))
      o.sequences = JsonIntegerOrThrow<uint32_t>(j["sequences"], "sequences");
    if (j.contains("frames")) o.frames = JsonIntegerOrThrow<uint32_t>(j["frames"], "frames");
    o.fps = j.value("fps", o.fps);
    if (j.contains("keyposes_every")) {
      o.keyposes_every = JsonIntegerOrThrow<uint32_t>(j["keyposes_every"], "keyposes_every");
    }
    o.turn_deg_per_frame = j.value("turn_deg_per_frame", o.turn_deg_per_frame);
    o.roll_deg_per_frame = j.value("roll_deg_per_frame", o.roll_deg_per_frame);
    const std::string backgrounds = j.value("backgrounds", std::string("alternate"));
    o.backgrounds = backgrounds == "plain"       ? SequenceBackgrounds::kPlain
                    : backgrounds == "cluttered" ? SequenceBackgrounds::kCluttered
                                                 : SequenceBackgrounds::kAlternate;
    if (j.contains("leave")) {
      const nlohmann::json& l = j["leave"];
      for (const auto& s : l.at("sequences")) {
        o.leave.sequences.push_back(JsonIntegerOrThrow<uint32_t>(s, "leave.sequences"));
      }
      o.leave.start = l.value("start", o.leave.start);
      if (l.contains("move_frames")) {
        o.leave.move_frames = JsonIntegerOrThrow<uint32_t>(l["move_frames"], "leave.move_frames");
      }
      if (l.contains("out_frames")) {
        o.leave.out_frames = JsonIntegerOrThrow<uint32_t>(l["out_frames"], "leave.out_frames");
      }
      o.leave.distance = l.value("distance", o.leave.distance);
    }
  } catch (const JsonRangeError& e) {
    return SequenceConfigError(what, e.what());
  }
  for (uint32_t s : o.leave.sequences) {
    if (s >= o.sequences) {
      return SequenceConfigError(what,
                                 "leave.sequences names sequence " + std::to_string(s) + " of " +
                                     std::to_string(o.sequences) + " (they are numbered from 0)");
    }
  }
  if (!o.leave.sequences.empty()) {
    const uint32_t first = static_cast<uint32_t>(std::lround(o.leave.start * o.frames));
    const uint64_t end =
        static_cast<uint64_t>(first) + 2ull * o.leave.move_frames + o.leave.out_frames;
    if (end >= o.frames) {
      return SequenceConfigError(what,
                                 "the leave stretch (from frame " + std::to_string(first) + ", " +
                                     std::to_string(2 * o.leave.move_frames + o.leave.out_frames) +
                                     " frames) must end before the last of the " +
                                     std::to_string(o.frames) +
                                     " frames, so the hand is seen coming back");
    }
  }
  if (!o.Check()) return SequenceConfigError(what, "bad options");
  return o;
}

nlohmann::json SequenceOptions::ToJson() const {
  const char* names[] = {"plain", "cluttered", "alternate"};
  nlohmann::json j = {{"sequences", sequences},
                      {"frames", frames},
                      {"fps", fps},
                      {"keyposes_every", keyposes_every},
                      {"turn_deg_per_frame", turn_deg_per_frame},
                      {"roll_deg_per_frame", roll_deg_per_frame},
                      {"backgrounds", names[static_cast<int>(backgrounds)]}};
  if (!leave.sequences.empty()) {
    j["leave"] = {{"sequences", leave.sequences},
                  {"start", leave.start},
                  {"move_frames", leave.move_frames},
                  {"out_frames", leave.out_frames},
                  {"distance", leave.distance}};
  }
  return j;
}

std::vector<SequenceFrame> PlanSequenceFrames(const SequenceOptions& options,
                                              const NaturalPoseOptions& natural,
                                              const JointLimits& limits,
                                              uint64_t seed,
                                              int resolution,
                                              const std::array<double, 3>& forward_axis,
                                              const std::array<double, 3>& palm_normal) {
  THROW_CHECK(options.Check());
  THROW_CHECK(natural.Check());
  std::vector<SequenceFrame> frames;
  frames.reserve(static_cast<size_t>(options.sequences) * options.frames);
  const double deg = M_PI / 180.0;
  for (uint32_t s = 0; s < options.sequences; ++s) {
    const uint64_t sequence_seed = DeriveSeed(seed, kSequenceStream, s);
    Rng rng(sequence_seed);
    const double z = 2.0 * rng.Uniform() - 1.0;
    const double phi = 2.0 * M_PI * rng.Uniform();
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const Vec3 d0 = {r * std::cos(phi), r * std::sin(phi), z};
    // The turn axis: a uniform angle in the plane perpendicular to d0.
    const Vec3 helper = std::abs(d0[2]) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0};
    const Vec3 u = Normalised(Cross(d0, helper));
    const Vec3 v = Cross(d0, u);
    const double axis_angle = 2.0 * M_PI * rng.Uniform();
    const Vec3 axis = Normalised({u[0] * std::cos(axis_angle) + v[0] * std::sin(axis_angle),
                                  u[1] * std::cos(axis_angle) + v[1] * std::sin(axis_angle),
                                  u[2] * std::cos(axis_angle) + v[2] * std::sin(axis_angle)});
    const double roll0 = 2.0 * M_PI * rng.Uniform();
    const double roll_sense = rng.Uniform() < 0.5 ? -1.0 : 1.0;
    const double leave_angle = 2.0 * M_PI * rng.Uniform();
    auto camera0 = CamFromHandRotation(d0, forward_axis, palm_normal, roll0);
    THROW_CHECK_MSG(camera0.ok(), "sequence camera: " + camera0.status().ToString());
    const Vec3 x0 = (*camera0)[0];

    NaturalPoseOptions keypose_options = natural;
    keypose_options.seed = sequence_seed;
    const uint32_t num_keyposes =
        (options.frames - 1 + options.keyposes_every - 1) / options.keyposes_every + 1;
    std::vector<NaturalPose> keyposes;
    for (uint32_t k = 0; k < num_keyposes; ++k) {
      keyposes.push_back(SampleNaturalPose(keypose_options, limits, k));
    }
    const bool leaves =
        std::find(options.leave.sequences.begin(), options.leave.sequences.end(), s) !=
        options.leave.sequences.end();
    const uint32_t leave_first =
        static_cast<uint32_t>(std::lround(options.leave.start * options.frames));
    const bool clutter = options.backgrounds == SequenceBackgrounds::kCluttered ||
                         (options.backgrounds == SequenceBackgrounds::kAlternate && s % 2 == 1);

    for (uint32_t f = 0; f < options.frames; ++f) {
      SequenceFrame frame;
      frame.sequence = s;
      frame.frame = f;
      frame.time = f / options.fps;
      frame.seed = sequence_seed;
      frame.clutter = clutter;
      const uint32_t k = f / options.keyposes_every;
      const double w =
          Smoothstep(static_cast<double>(f % options.keyposes_every) / options.keyposes_every);
      const NaturalPose& a = keyposes[k];
      const NaturalPose& b = keyposes[std::min<size_t>(k + 1, keyposes.size() - 1)];
      for (int j = 0; j < kNumJointAngles; ++j) {
        frame.joints[j] = a.joints[j] + w * (b.joints[j] - a.joints[j]);
      }
      frame.clamped = a.clamped || b.clamped;
      // The camera turns rigidly with the direction (its x axis carried along by the same
      // rotation), then rolls: a roll number kept fixed would spin the picture where the up rule
      // changes fast, near the forward axis (docs/conventions.md).
      const double turn = options.turn_deg_per_frame * deg * f;
      frame.direction = TurnAbout(d0, axis, turn);
      const double carried =
          RollForCameraX(frame.direction, TurnAbout(x0, axis, turn), forward_axis, palm_normal);
      frame.roll =
          std::fmod(carried + roll_sense * options.roll_deg_per_frame * deg * f, 2.0 * M_PI);
      if (frame.roll < 0) frame.roll += 2.0 * M_PI;
      if (frame.roll >= 2.0 * M_PI) frame.roll = 0;
      if (leaves) {
        const double share = LeaveShare(options.leave, leave_first, f);
        const double shift = share * options.leave.distance * resolution;
        frame.photo_offset_px = {shift * std::cos(leave_angle), shift * std::sin(leave_angle)};
        frame.leaving = share > 0;
      }
      frames.push_back(frame);
    }
  }
  return frames;
}

}  // namespace handdb
