#include "evaluate/sequence_track.h"

#include <utility>

#include "base/status.h"

namespace handdb {
namespace {

// A sequence's frames from their photos' paths, with the test set's times.
class SequenceFrames : public FrameSource {
 public:
  SequenceFrames(const std::vector<SequenceFrameInput>& frames, double fps)
      : frames_(frames), fps_(fps) {}

  Result<bool> Next(Frame* frame) override {
    if (next_ >= frames_.size()) return false;
    const SequenceFrameInput& in = frames_[next_];
    *frame = Frame{};
    frame->index = static_cast<int64_t>(next_);
    frame->time_s = in.time;
    frame->name = in.photo.string();
    frame->path = in.photo;
    ++next_;
    return true;
  }
  int64_t size_hint() const override { return static_cast<int64_t>(frames_.size()); }
  double fps() const override { return fps_; }

 private:
  const std::vector<SequenceFrameInput>& frames_;
  double fps_;
  size_t next_ = 0;
};

}  // namespace

FramePrediction PredictionOfTrackFrame(const TrackFrame& frame) {
  FramePrediction p;
  if (!frame.has_pose || frame.chosen < 0 || frame.chosen >= static_cast<int>(frame.matches.size()))
    return p;
  p.found = true;
  p.keypoints_px = frame.keypoints_image_px;
  p.keypoints = frame.keypoints_3d;
  if (frame.fit.best == 0) {
    p.joint_angles = frame.fit.fits[0].fit.joints;
    return p;
  }
  const Match& m = frame.matches[frame.chosen];
  for (int k = 0; k < kNumJointAngles; ++k) p.joint_angles[k] = m.label.joint_angles[k];
  return p;
}

SequencePredictor MakeTrackerPredictor(const Searcher& searcher, TrackOptions options) {
  THROW_CHECK(options.Check());
  return [&searcher, options = std::move(options)](
             const std::vector<SequenceFrameInput>& frames,
             double fps,
             std::vector<double>* seconds,
             const std::function<void()>& frame_done) -> Result<std::vector<FramePrediction>> {
    SequenceFrames source(frames, fps);
    std::vector<FramePrediction> predictions;
    auto on_frame = [&](const TrackFrame& frame) -> Status {
      predictions.push_back(PredictionOfTrackFrame(frame));
      seconds->push_back(frame.seconds);
      frame_done();
      return Status::Ok();
    };
    auto summary = TrackFrames(searcher, source, options, on_frame);
    if (!summary.ok()) return summary.status();
    return predictions;
  };
}

}  // namespace handdb
