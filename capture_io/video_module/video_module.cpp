// libtbsp_video: OpenCV's video decoding (VideoCapture) behind a small C interface. tbsp_capture_io
// loads it with dlopen the first time a studio names a video file (src/video_reader.cpp), so that
// programs which read no video do not load OpenCV's video stack: libopencv_videoio brings 98 of
// the 313 shared libraries the tbsp CLI loaded at start-up (FFmpeg, GStreamer, their codecs).
// Exceptions stay inside: every entry point reports failure by its return value.
#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#define TBSP_VIDEO_API extern "C" __attribute__((visibility("default")))

namespace {
cv::VideoCapture* cap(void* h) { return static_cast<cv::VideoCapture*>(h); }
}  // namespace

/// Version of this interface; the loader refuses another.
TBSP_VIDEO_API int tbsp_video_abi_version() { return 1; }

/// Opens `path`; null when OpenCV cannot open it.
TBSP_VIDEO_API void* tbsp_video_open(const char* path) {
  try {
    auto* c = new cv::VideoCapture(path);
    if (c->isOpened()) return c;
    delete c;
  } catch (...) {
  }
  return nullptr;
}

/// cv::VideoCapture::get(prop); 0 on failure.
TBSP_VIDEO_API double tbsp_video_get(void* h, int prop) {
  try {
    return cap(h)->get(prop);
  } catch (...) {
    return 0;
  }
}

/// Skips one frame; 1 when there was one.
TBSP_VIDEO_API int tbsp_video_grab(void* h) {
  try {
    return cap(h)->grab() ? 1 : 0;
  } catch (...) {
    return 0;
  }
}

/// Decodes the next frame into *out (BGR); 1 when there was one.
TBSP_VIDEO_API int tbsp_video_read(void* h, cv::Mat* out) {
  try {
    return cap(h)->read(*out) ? 1 : 0;
  } catch (...) {
    return 0;
  }
}

TBSP_VIDEO_API void tbsp_video_close(void* h) { delete cap(h); }
