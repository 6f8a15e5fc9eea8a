// Hand landmarks of a photo: the 21 joints (wrist, then 4 per finger from the thumb, base to
// tip: the order of docs/conventions.md) found by a pretrained landmark network, MediaPipe
// Hands' `hand_landmark_full.tflite` (Apache-2.0, installed by scripts/deps.sh), run by
// nn/tflite.h. The photo path crops the hand it segmented (its silhouette's centre,
// 1.5 diameters wide, turned so the hand points up: away from the forearm, or from the palm
// centre towards the silhouette's centre), runs the network again on the crop those joints give
// (CropAroundLandmarks) and maps the joints back to the picture's pixels. The search uses them
// to re-rank its nearest views (pose/landmark_rank.h, docs/query.md), the pose fit fits the rig
// to them (pose/fit.h).
#pragma once

#include <array>
#include <filesystem>
#include <memory>

#include "base/status.h"
#include "format/roll.h"

namespace handdb {

inline constexpr int kNumLandmarks = 21;

// A square crop of a picture, turned: centre and side in the picture's px, and the turn
// (degrees, clockwise in the picture) that brings the hand's up to the crop's up.
struct LandmarkCrop {
  Point2f centre{};
  float side = 0;
  float angle_deg = 0;
};

struct HandLandmarks {
  // The joints in the source picture's px (pixel centres at integer + 0.5, like
  // QueryEdges::ImageFromNormalised), in the order of docs/conventions.md.
  std::array<Point2f, kNumLandmarks> image_px{};
  // The network's hand-presence score in [0, 1]: below ~0.9 the joints are unreliable (it sees
  // no hand, or a view it was not trained on) and the search does not use them.
  float presence = 0;
  // Depth, which the 2D joints leave open (the pose fit's optional depth term reads the world
  // joints, pose/fit.h; docs/decisions/0019 measures both against the truth): the network's
  // world joints (metres, origin near the hand's centre, z away from the camera), turned from
  // the crop's axes into the picture's, so x is right and y down as in image_px. False when the
  // model has no world output; a NaN joint is the network's, kept as it is.
  bool has_world = false;
  std::array<std::array<float, 3>, kNumLandmarks> world_m{};
  // The network's relative depth of each joint in the picture's px (its screen joints' z,
  // scaled from the crop as x and y are; away from the camera, the wrist near 0).
  std::array<float, kNumLandmarks> depth_px{};
  // The network's handedness score: above 0.5 for a right hand in the picture as it is
  // (measured on right- and left-hand renders, docs/decisions/0029); -1 when the model has no
  // such output.
  float handedness = -1;
  // The crop the network saw, in source px.
  LandmarkCrop crop;
};

// The crop MediaPipe Hands takes around a hand it has found (its landmarks-to-ROI rule, with
// which it tracks a hand from frame to frame and for which the network was trained): turned so
// the wrist points down to the mean of the middle knuckle and the mean of the index and ring
// knuckles, centred on the box of the palm's and the digits' first joints (wrist, the thumb's
// first three, each finger's first two) in that turn, shifted a tenth of the box towards the
// fingers, and twice the box's longer side wide.
LandmarkCrop CropAroundLandmarks(const HandLandmarks& landmarks);

class TfliteModel;

class HandLandmarker {
 public:
  // Loads a landmark model: one 1xHxWx3 float input (RGB in [0, 1]), outputs 21 x 3 joint
  // coordinates in the input's px and a presence score, and, when a later output has 21 x 3
  // values (MediaPipe's fourth, after the handedness), the world joints. Errors name the file.
  static Result<std::shared_ptr<const HandLandmarker>> Open(const std::filesystem::path& model);
  // The installed default: $HANDDB_LANDMARK_MODEL if set, else
  // third_party/assets/mediapipe-hands/hand_landmark_full.tflite under the source tree
  // (RepoRoot(): $HANDDB_SOURCE_DIR or the one this binary was built from).
  static std::filesystem::path DefaultModelPath();

  ~HandLandmarker();
  const std::filesystem::path& path() const { return path_; }

  // The landmarks of the hand in `rgb` (8-bit RGB rows, `width` x `height`, `stride` bytes per
  // row) inside `crop` (px). Thread-safe.
  HandLandmarks Detect(
      const uint8_t* rgb, int width, int height, size_t stride, const LandmarkCrop& crop) const;

 private:
  HandLandmarker(std::filesystem::path path, std::unique_ptr<TfliteModel> model);
  std::filesystem::path path_;
  std::unique_ptr<TfliteModel> model_;
  int input_h_ = 0, input_w_ = 0;
  int world_output_ = -1;       // the world joints' output, -1: none
  int handedness_output_ = -1;  // the handedness score's output, -1: none
};

}  // namespace handdb
