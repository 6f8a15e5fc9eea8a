#include "photo/hand_landmarks.h"

#include <cmath>
#include <cstdlib>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "base/repo_root.h"
#include "nn/tflite.h"

namespace handdb {

HandLandmarker::HandLandmarker(std::filesystem::path path, std::unique_ptr<TfliteModel> model)
    : path_(std::move(path)), model_(std::move(model)) {
  input_h_ = model_->input_shape()[1];
  input_w_ = model_->input_shape()[2];
  const std::vector<size_t> sizes = model_->output_sizes();
  if (sizes.size() > 2 && sizes[2] == 1) handedness_output_ = 2;
  for (size_t i = sizes.size(); i-- > 2;) {
    if (sizes[i] == 3 * kNumLandmarks) {
      world_output_ = static_cast<int>(i);
      break;
    }
  }
}

HandLandmarker::~HandLandmarker() = default;

std::filesystem::path HandLandmarker::DefaultModelPath() {
  if (const char* env = std::getenv("HANDDB_LANDMARK_MODEL"); env != nullptr && *env != '\0') {
    return env;
  }
  return RepoRoot() / "third_party" / "assets" / "mediapipe-hands" / "hand_landmark_full.tflite";
}

Result<std::shared_ptr<const HandLandmarker>> HandLandmarker::Open(
    const std::filesystem::path& model) {
  auto m = TfliteModel::Load(model);
  if (!m.ok()) return m.status();
  const std::vector<int>& in = m->input_shape();
  const std::vector<size_t> out = m->output_sizes();
  if (in.size() != 4 || in[0] != 1 || in[3] != 3 || in[1] < 16 || in[2] < 16 || in[1] > 1024 ||
      in[2] > 1024 || out.size() < 2 || out[0] != 3 * kNumLandmarks || out[1] != 1) {
    return Status(StatusCode::kSizeMismatch,
                  model.string() +
                      ": not a hand landmark model (expected one 1xHxWx3 input, and 63 joint "
                      "coordinates and a presence score as its first two outputs)");
  }
  return std::shared_ptr<const HandLandmarker>(
      new HandLandmarker(model, std::make_unique<TfliteModel>(std::move(m).value())));
}

HandLandmarks HandLandmarker::Detect(
    const uint8_t* rgb, int width, int height, size_t stride, const LandmarkCrop& crop) const {
  const Point2f centre = crop.centre;
  const float side = crop.side;
  const cv::Mat picture(height, width, CV_8UC3, const_cast<uint8_t*>(rgb), stride);
  // picture -> crop: turn by -angle about `centre`, scale to the network's input, centre it.
  // OpenCV's pixel centres are at integers; ours at integer + 0.5.
  const double a = crop.angle_deg * M_PI / 180.0;
  const double s = static_cast<double>(input_w_) / side;
  const double sy = static_cast<double>(input_h_) / side;
  cv::Matx23d m(std::cos(a) * s, std::sin(a) * s, 0, -std::sin(a) * sy, std::cos(a) * sy, 0);
  const double cx = centre.x - 0.5, cy = centre.y - 0.5;
  m(0, 2) = input_w_ / 2.0 - (m(0, 0) * cx + m(0, 1) * cy);
  m(1, 2) = input_h_ / 2.0 - (m(1, 0) * cx + m(1, 1) * cy);
  cv::Mat pixels;
  cv::warpAffine(
      picture, pixels, m, cv::Size(input_w_, input_h_), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  std::vector<float> input(static_cast<size_t>(input_w_) * input_h_ * 3);
  pixels.convertTo(cv::Mat(input_h_, input_w_, CV_32FC3, input.data()), CV_32F, 1.0 / 255.0);
  // One workspace per thread and model: buffers are reused from photo to photo.
  thread_local std::map<const TfliteModel*, std::unique_ptr<TfliteModel::Workspace>> workspaces;
  std::unique_ptr<TfliteModel::Workspace>& ws = workspaces[model_.get()];
  if (!ws) ws = model_->NewWorkspace();
  const std::vector<std::vector<float>> out = model_->Run(input, ws.get());
  cv::Matx23d inv;
  cv::invertAffineTransform(m, inv);
  HandLandmarks lm;
  for (int k = 0; k < kNumLandmarks; ++k) {
    const double x = out[0][3 * k], y = out[0][3 * k + 1];
    lm.image_px[k] = {static_cast<float>(inv(0, 0) * x + inv(0, 1) * y + inv(0, 2) + 0.5),
                      static_cast<float>(inv(1, 0) * x + inv(1, 1) * y + inv(1, 2) + 0.5)};
    lm.depth_px[k] = static_cast<float>(out[0][3 * k + 2] / s);
  }
  if (world_output_ >= 0) {
    // The world joints' x and y are the crop's axes: the crop's turn undone, as for image_px.
    lm.has_world = true;
    const double c = std::cos(a), sn = std::sin(a);
    const std::vector<float>& w = out[static_cast<size_t>(world_output_)];
    for (int k = 0; k < kNumLandmarks; ++k) {
      const double x = w[3 * k], y = w[3 * k + 1];
      lm.world_m[k] = {
          static_cast<float>(c * x - sn * y), static_cast<float>(sn * x + c * y), w[3 * k + 2]};
    }
  }
  lm.presence = out[1][0];
  if (handedness_output_ >= 0) lm.handedness = out[static_cast<size_t>(handedness_output_)][0];
  lm.crop = crop;
  return lm;
}

LandmarkCrop CropAroundLandmarks(const HandLandmarks& landmarks) {
  const auto& p = landmarks.image_px;
  // The hand's up: from the wrist to the mean of the middle knuckle (9) and the mean of the index
  // (5) and ring (13) knuckles.
  const double ux = 0.5 * (p[9].x + 0.5 * (p[5].x + p[13].x)) - p[0].x;
  const double uy = 0.5 * (p[9].y + 0.5 * (p[5].y + p[13].y)) - p[0].y;
  const double angle = std::atan2(ux, -uy);  // clockwise from the picture's up
  // The crop's axes in the picture: right (c, s) and down (-s, c).
  const double c = std::cos(angle), s = std::sin(angle);
  double lo_x = 1e30, hi_x = -1e30, lo_y = 1e30, hi_y = -1e30;
  for (const int k : {0, 1, 2, 3, 5, 6, 9, 10, 13, 14, 17, 18}) {
    const double x = c * p[k].x + s * p[k].y, y = -s * p[k].x + c * p[k].y;
    lo_x = std::min(lo_x, x);
    hi_x = std::max(hi_x, x);
    lo_y = std::min(lo_y, y);
    hi_y = std::max(hi_y, y);
  }
  // The box's centre, shifted up the crop by a tenth of its height, back in the picture's axes.
  const double bx = 0.5 * (lo_x + hi_x), by = 0.5 * (lo_y + hi_y) - 0.1 * (hi_y - lo_y);
  LandmarkCrop crop;
  crop.centre = {static_cast<float>(c * bx - s * by), static_cast<float>(s * bx + c * by)};
  crop.side = static_cast<float>(2.0 * std::max(hi_x - lo_x, hi_y - lo_y));
  crop.angle_deg = static_cast<float>(angle * 180.0 / M_PI);
  return crop;
}

}  // namespace handdb
