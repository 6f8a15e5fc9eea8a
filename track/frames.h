// The frames of a video or of a folder of pictures, one at a time, in order. A frame that is
// missing or cannot be decoded is still a frame (its index and time, and the error): a tracker
// reports it and goes on.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "base/status.h"
#include "photo/image_edges.h"

namespace handdb {

struct Frame {
  int64_t index = 0;  // 0-based, in the video's (or the folder's numbering's) order
  double time_s = 0;  // presentation time
  std::string name;   // a folder's picture path, or "VIDEO#index"
  // Where the pixels are: `path` (a folder's picture, read by the photo path from its file) or
  // `pixels` (a decoded video frame, valid until the next Next()).
  std::filesystem::path path;
  bool has_pixels = false;
  PicturePixels pixels;
  Status error;  // not ok: a missing or undecodable frame (its index and time still hold)
};

struct FrameSourceOptions {
  // A folder's frames per second (their times are index / fps); a video's own rate wins.
  double folder_fps = 30;
  bool Check() const;
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // The next frame into *frame: true, or false at the end. An error of the source itself (a
  // video that stops decoding for good) ends it as a Status.
  virtual Result<bool> Next(Frame* frame) = 0;
  // The frames expected (-1: unknown), for progress.
  virtual int64_t size_hint() const = 0;
  virtual double fps() const = 0;
};

// Whether a folder file is a frame: png, jpg, jpeg, pnm, pgm, ppm, bmp (case-insensitive).
bool IsFrameFileName(const std::string& name);

// A folder's frames: its picture files sorted by name. When every name ends in a number (before
// the extension) and the numbers differ, a frame's index is its number less the first one's, so
// a number missing from the run is a frame with a kNotFound error; otherwise the index is the
// position in the sorted list.
Result<std::unique_ptr<FrameSource>> OpenFrameFolder(const std::filesystem::path& dir,
                                                     const FrameSourceOptions& options = {});

// A video file through the video plugin (track/videoio_plugin.h), opened on first use; its
// absence is one error naming where it was looked for (kNotFound).
Result<std::unique_ptr<FrameSource>> OpenVideo(const std::filesystem::path& video);

// A folder (OpenFrameFolder) or a video file (OpenVideo). kNotFound: no such path.
Result<std::unique_ptr<FrameSource>> OpenFrames(const std::filesystem::path& video_or_dir,
                                                const FrameSourceOptions& options = {});

// Where the video plugin is looked for (base/plugin.h): $HANDDB_VIDEOIO_PLUGIN alone when set;
// else, in order, beside the running executable, in its ../lib/handdb, beside the shared object
// holding the loader (the Python module), then the build tree's.
std::vector<std::filesystem::path> VideoPluginCandidates();

}  // namespace handdb
