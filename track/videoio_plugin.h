// The C interface of the video plugin (libhanddb_videoio.so, track/videoio_plugin.cc): OpenCV's
// videoio over Debian's ffmpeg, which pulls ~100 shared libraries into a process, so the handdb
// binary and the Python module never link it; track/frames.cc opens the plugin (dlopen) on the
// first video. Plain C types only: the plugin and its loader agree on nothing else.
#pragma once

#include <stddef.h>
#include <stdint.h>

extern "C" {

// Bumped when a function's meaning or signature changes; the loader refuses another version.
#define HANDDB_VIDEOIO_ABI 1

struct handdb_video;

// The ABI version the plugin was built with.
int handdb_videoio_abi(void);

// Opens a video file; null on failure with a message in error (at most error_size bytes,
// terminated).
struct handdb_video* handdb_video_open(const char* path, char* error, size_t error_size);

// Frames per second (0: unknown) and the frame count the container states (-1: unknown).
void handdb_video_info(const struct handdb_video* video, double* fps, int64_t* frame_count);

// The next frame, 8-bit BGR, valid until the next call: 1 a frame, 0 the end of the video, -1 a
// frame that could not be decoded (the video goes on at the next one). time_s: the frame's
// presentation time (seconds).
int handdb_video_read(struct handdb_video* video,
                      const uint8_t** bgr,
                      int* width,
                      int* height,
                      size_t* row_bytes,
                      double* time_s);

void handdb_video_close(struct handdb_video* video);
}
