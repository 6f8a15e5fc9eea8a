// libhanddb_videoio.so: track/videoio_plugin.h over OpenCV's VideoCapture. Only this file links
// opencv_videoio.
#include "track/videoio_plugin.h"

#include <cstdio>
#include <exception>
#include <opencv2/core/mat.hpp>
#include <opencv2/videoio.hpp>
#include <string>

struct handdb_video {
  cv::VideoCapture capture;
  cv::Mat frame;
  int64_t frame_count = -1;
  int64_t next = 0;  // the index of the next frame to read
  double fps = 0;
};

namespace {

void SetError(char* error, size_t error_size, const std::string& message) {
  if (error != nullptr && error_size > 0) std::snprintf(error, error_size, "%s", message.c_str());
}

}  // namespace

extern "C" {

int handdb_videoio_abi(void) { return HANDDB_VIDEOIO_ABI; }

handdb_video* handdb_video_open(const char* path, char* error, size_t error_size) {
  try {
    auto* video = new handdb_video;
    if (!video->capture.open(path, cv::CAP_FFMPEG) || !video->capture.isOpened()) {
      delete video;
      SetError(error, error_size, "not a video OpenCV's ffmpeg backend can open");
      return nullptr;
    }
    video->fps = video->capture.get(cv::CAP_PROP_FPS);
    const double count = video->capture.get(cv::CAP_PROP_FRAME_COUNT);
    video->frame_count = count > 0 ? static_cast<int64_t>(count) : -1;
    return video;
  } catch (const std::exception& e) {
    SetError(error, error_size, e.what());
    return nullptr;
  }
}

void handdb_video_info(const handdb_video* video, double* fps, int64_t* frame_count) {
  if (fps != nullptr) *fps = video->fps > 0 ? video->fps : 0;
  if (frame_count != nullptr) *frame_count = video->frame_count;
}

int handdb_video_read(handdb_video* video,
                      const uint8_t** bgr,
                      int* width,
                      int* height,
                      size_t* row_bytes,
                      double* time_s) {
  try {
    const int64_t index = video->next++;
    if (!video->capture.grab()) {
      // The stated count says whether this is the end or a frame that does not decode.
      if (video->frame_count < 0 || index >= video->frame_count) return 0;
      return -1;
    }
    if (time_s != nullptr) {
      const double ms = video->capture.get(cv::CAP_PROP_POS_MSEC);
      *time_s = ms >= 0 ? ms / 1000.0 : (video->fps > 0 ? index / video->fps : 0);
    }
    if (!video->capture.retrieve(video->frame) || video->frame.empty() ||
        video->frame.type() != CV_8UC3) {
      return -1;
    }
    *bgr = video->frame.data;
    *width = video->frame.cols;
    *height = video->frame.rows;
    *row_bytes = video->frame.step[0];
    return 1;
  } catch (const std::exception&) {
    return -1;
  }
}

void handdb_video_close(handdb_video* video) { delete video; }
}
