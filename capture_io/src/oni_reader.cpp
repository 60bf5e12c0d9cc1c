#include <cmath>
#include <filesystem>
#include <mutex>

#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/io/depth_io.h"

#ifdef TBSP_HAVE_OPENNI2
#include <OpenNI.h>
#endif

namespace tbsp {

#ifdef TBSP_HAVE_OPENNI2

namespace {
// OpenNI2 is a process-wide singleton; initialise once and keep it (shutdown at exit is
// left to the OS: OpenNI2 cannot be re-initialised reliably after shutdown).
void init_openni() {
  static std::once_flag once;
  static openni::Status status = openni::STATUS_OK;
  std::call_once(once, [] { status = openni::OpenNI::initialize(); });
  if (status != openni::STATUS_OK)
    throw FileError(std::string("OpenNI2 failed to initialise: ") + openni::OpenNI::getExtendedError() +
                    " (are the OpenNI2 drivers installed? Debian package libopenni2-0)");
}
}  // namespace

struct OniReader::Impl {
  std::string path;
  openni::Device device;
  openni::VideoStream depth, color;
  OniInfo info;
  int next = 0;
  static void park(std::unique_ptr<Impl> impl);
};

OniReader::OniReader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw FileError("'" + path + "': no such file; check the path");
  init_openni();
  Impl& d = *impl_;
  d.path = path;
  if (d.device.open(path.c_str()) != openni::STATUS_OK) {
    const std::string why = openni::OpenNI::getExtendedError();
    throw FileError("'" + path + "': OpenNI2 cannot open this recording" + (why.empty() ? std::string(" (empty or corrupt .oni file)") : ": " + why));
  }
  openni::PlaybackControl* pc = d.device.getPlaybackControl();
  if (!pc) throw FileError("'" + path + "': not a recording (OpenNI2 gives no playback control)");
  pc->setSpeed(-1.0f);
  pc->setRepeatEnabled(false);
  OniInfo& in = d.info;
  if (d.device.hasSensor(openni::SENSOR_DEPTH) && d.depth.create(d.device, openni::SENSOR_DEPTH) == openni::STATUS_OK) {
    in.has_depth = true;
    in.depth_frames = pc->getNumberOfFrames(d.depth);
    const openni::VideoMode vm = d.depth.getVideoMode();
    in.depth_width = vm.getResolutionX();
    in.depth_height = vm.getResolutionY();
    in.fps = vm.getFps();
    const auto fmt = vm.getPixelFormat();
    if (fmt == openni::PIXEL_FORMAT_DEPTH_100_UM) in.depth_scale = 1e-4;
    else if (fmt == openni::PIXEL_FORMAT_DEPTH_1_MM) in.depth_scale = 1e-3;
    else throw FileError("'" + path + "': depth pixel format " + std::to_string(fmt) + " is not a 16-bit depth format");
    const double hfov = d.depth.getHorizontalFieldOfView(), vfov = d.depth.getVerticalFieldOfView();
    if (!(hfov > 0) || !(vfov > 0)) throw FileError("'" + path + "': the depth stream has no field of view; intrinsics unknown");
    in.depth_intrinsics.fx = 0.5 * in.depth_width / std::tan(0.5 * hfov);
    in.depth_intrinsics.fy = 0.5 * in.depth_height / std::tan(0.5 * vfov);
    in.depth_intrinsics.cx = 0.5 * (in.depth_width - 1);
    in.depth_intrinsics.cy = 0.5 * (in.depth_height - 1);
  }
  if (d.device.hasSensor(openni::SENSOR_COLOR) && d.color.create(d.device, openni::SENSOR_COLOR) == openni::STATUS_OK) {
    const openni::VideoMode vm = d.color.getVideoMode();
    if (vm.getPixelFormat() == openni::PIXEL_FORMAT_RGB888) {
      in.has_color = true;
      in.color_frames = pc->getNumberOfFrames(d.color);
      in.color_width = vm.getResolutionX();
      in.color_height = vm.getResolutionY();
    } else {
      logger()->warn("'{}': colour pixel format {} is not RGB888; colour is not replayed", path, static_cast<int>(vm.getPixelFormat()));
      d.color.destroy();
    }
  }
  if (!in.has_depth || in.depth_frames <= 0)
    throw FileError("'" + path + "': the recording has no depth frames (depth stream: " + (in.has_depth ? "yes" : "no") +
                    ", " + std::to_string(in.depth_frames) + " frames; colour frames: " + std::to_string(in.color_frames) + ")");
  if (d.depth.start() != openni::STATUS_OK) throw FileError("'" + path + "': cannot start the depth stream: " + openni::OpenNI::getExtendedError());
  if (in.has_color && d.color.start() != openni::STATUS_OK) in.has_color = false;
}

// OpenNI2's file driver cannot be torn down safely: its player thread walks the stream list
// without a lock and, when Device::close() wakes it from its manual-trigger wait, delivers one
// more frame into streams that are being destroyed (a segfault in libOniFile / libOpenNI2 in
// about 1 of 50 closes, whatever the order of stop/destroy/close; draining the recording first
// does not avoid it). So a finished reader is parked instead: its device and streams stay
// open, the player thread sleeps on its trigger, and the process exit reclaims them. The cost
// is one idle thread, a file handle and the stream buffers (a few MB) per reader.
void OniReader::Impl::park(std::unique_ptr<Impl> impl) {
  static std::mutex m;
  static auto* parked = new std::vector<std::unique_ptr<Impl>>();  // never destroyed, on purpose
  std::lock_guard<std::mutex> lock(m);
  parked->push_back(std::move(impl));
}

OniReader::~OniReader() {
  if (impl_) Impl::park(std::move(impl_));
}
const OniInfo& OniReader::info() const { return impl_->info; }
bool OniReader::available() { return true; }

bool OniReader::next(OniFrame& f) {
  Impl& d = *impl_;
  if (d.next >= d.info.depth_frames) return false;
  openni::VideoFrameRef ref;
  int idx = 0;
  openni::VideoStream* s = &d.depth;
  if (openni::OpenNI::waitForAnyStream(&s, 1, &idx, 5000) != openni::STATUS_OK || d.depth.readFrame(&ref) != openni::STATUS_OK)
    throw FileError("'" + d.path + "': reading depth frame " + std::to_string(d.next) + " failed: " + openni::OpenNI::getExtendedError());
  cv::Mat(ref.getHeight(), ref.getWidth(), CV_16UC1, const_cast<void*>(ref.getData()), static_cast<std::size_t>(ref.getStrideInBytes()))
      .copyTo(f.depth);
  f.index = d.next;
  f.color.release();
  if (d.info.has_color && d.next < d.info.color_frames) {
    openni::VideoFrameRef cref;
    openni::VideoStream* cs = &d.color;
    if (openni::OpenNI::waitForAnyStream(&cs, 1, &idx, 5000) == openni::STATUS_OK && d.color.readFrame(&cref) == openni::STATUS_OK) {
      cv::Mat rgb(cref.getHeight(), cref.getWidth(), CV_8UC3, const_cast<void*>(cref.getData()), static_cast<std::size_t>(cref.getStrideInBytes()));
      cv::cvtColor(rgb, f.color, cv::COLOR_RGB2BGR);
    }
  }
  ++d.next;
  return true;
}

#else  // no OpenNI2

struct OniReader::Impl {
  OniInfo info;
};
OniReader::OniReader(const std::string& path) {
  throw FileError("'" + path + "': tbsp was built without OpenNI2; install libopenni2-dev and rebuild to replay .oni files");
}
OniReader::~OniReader() = default;
const OniInfo& OniReader::info() const { return impl_->info; }
bool OniReader::available() { return false; }
bool OniReader::next(OniFrame&) { return false; }

#endif

}  // namespace tbsp
