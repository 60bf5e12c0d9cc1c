#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include <poll.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/io/depth_io.h"

#ifdef TBSP_HAVE_OPENNI2
#include <OpenNI.h>
#endif

namespace tbsp {

#ifdef TBSP_HAVE_OPENNI2

// The OpenNI2 driver runs in a child process (fork), which sends frames over a socket pair.
// Why: OpenNI2's file player decodes frames on a thread of its own (libjpeg for compressed
// colour, its own codecs for depth); a corrupt frame can crash that thread, and a crash there
// cannot be caught in-process. In the child it only ends the child: the parent sees the socket
// close, reads the child's exit status and throws FileError naming the file and the frame.
// The child is also the cure for OpenNI2's unsafe teardown (a Device::close() racing its player
// thread segfaulted in ~1 of 50 closes): the parent never closes the driver, it kills the child.
//
// Protocol (child -> parent, native byte order, same machine): a header message with OniInfo,
// then for each request byte 'n' one message: kEnd, kError + text, or kFrame + index + depth
// (w, h, w*h uint16) + colour (w, h, w*h*3 BGR bytes; 0 x 0 when absent).

namespace {

enum MessageKind : std::int32_t { kInfo = 1, kFrame = 2, kEnd = 3, kError = 4 };

// Writes all of buf or returns false (peer gone). MSG_NOSIGNAL: a dead peer must not SIGPIPE us.
bool send_all(int fd, const void* buf, std::size_t n) {
  const char* p = static_cast<const char*>(buf);
  while (n > 0) {
    const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    p += w;
    n -= std::size_t(w);
  }
  return true;
}
template <class T>
bool send_pod(int fd, const T& v) {
  return send_all(fd, &v, sizeof(T));
}
bool send_error(int fd, const std::string& msg) {
  const std::int32_t k = kError, len = std::int32_t(msg.size());
  return send_pod(fd, k) && send_pod(fd, len) && send_all(fd, msg.data(), msg.size());
}

// ---- child side: OpenNI2 playback
struct Player {
  openni::Device device;
  openni::VideoStream depth, color;
  OniInfo info;
  int next = 0;
};

// Opens the recording; throws std::runtime_error with the message the parent will prefix with the path.
void open_player(const std::string& path, Player& d) {
  if (openni::OpenNI::initialize() != openni::STATUS_OK)
    throw std::runtime_error(std::string("OpenNI2 failed to initialise: ") + openni::OpenNI::getExtendedError() +
                             " (are the OpenNI2 drivers installed? Debian package libopenni2-0)");
  if (d.device.open(path.c_str()) != openni::STATUS_OK) {
    const std::string why = openni::OpenNI::getExtendedError();
    throw std::runtime_error("OpenNI2 cannot open this recording" + (why.empty() ? std::string(" (empty or corrupt .oni file)") : ": " + why));
  }
  openni::PlaybackControl* pc = d.device.getPlaybackControl();
  if (!pc) throw std::runtime_error("not a recording (OpenNI2 gives no playback control)");
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
    else throw std::runtime_error("depth pixel format " + std::to_string(fmt) + " is not a 16-bit depth format");
    const double hfov = d.depth.getHorizontalFieldOfView(), vfov = d.depth.getVerticalFieldOfView();
    if (!(hfov > 0) || !(vfov > 0)) throw std::runtime_error("the depth stream has no field of view; intrinsics unknown");
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
      std::fprintf(stderr, "tbsp: '%s': colour pixel format %d is not RGB888; colour is not replayed\n", path.c_str(),
                   static_cast<int>(vm.getPixelFormat()));
      d.color.destroy();
    }
  }
  if (!in.has_depth || in.depth_frames <= 0)
    throw std::runtime_error(std::string("the recording has no depth frames (depth stream: ") + (in.has_depth ? "yes" : "no") + ", " +
                             std::to_string(in.depth_frames) + " frames; colour frames: " + std::to_string(in.color_frames) + ")");
  if (d.depth.start() != openni::STATUS_OK)
    throw std::runtime_error(std::string("cannot start the depth stream: ") + openni::OpenNI::getExtendedError());
  if (in.has_color && d.color.start() != openni::STATUS_OK) in.has_color = false;
}

// Reads the next frame and sends it; false after kEnd or a failure (already reported).
bool send_next_frame(int fd, Player& d) {
  if (d.next >= d.info.depth_frames) {
    const std::int32_t k = kEnd;
    send_pod(fd, k);
    return false;
  }
  openni::VideoFrameRef ref;
  int idx = 0;
  openni::VideoStream* s = &d.depth;
  if (openni::OpenNI::waitForAnyStream(&s, 1, &idx, 5000) != openni::STATUS_OK || d.depth.readFrame(&ref) != openni::STATUS_OK) {
    send_error(fd, "reading depth frame " + std::to_string(d.next) + " failed: " + openni::OpenNI::getExtendedError());
    return false;
  }
  // rows are sent one by one (the frame's stride may pad them); no OpenCV in the child: its
  // thread pool, if the parent started one, does not survive fork()
  auto send_rows = [&](const openni::VideoFrameRef& r, std::size_t row_bytes) {
    const char* base = static_cast<const char*>(r.getData());
    for (int y = 0; y < r.getHeight(); ++y)
      if (!send_all(fd, base + std::size_t(y) * std::size_t(r.getStrideInBytes()), row_bytes)) return false;
    return true;
  };
  const std::int32_t k = kFrame, index = d.next, dw = ref.getWidth(), dh = ref.getHeight();
  if (!ref.getData() || dw <= 0 || dh <= 0 || ref.getStrideInBytes() < 2 * dw) {
    send_error(fd, "depth frame " + std::to_string(d.next) + " is empty or malformed (" + std::to_string(dw) + "x" +
                       std::to_string(dh) + ")");
    return false;
  }
  bool ok = send_pod(fd, k) && send_pod(fd, index) && send_pod(fd, dw) && send_pod(fd, dh) && send_rows(ref, 2 * std::size_t(dw));
  openni::VideoFrameRef cref;
  std::int32_t cw = 0, ch = 0;
  if (d.info.has_color && d.next < d.info.color_frames) {
    openni::VideoStream* cs = &d.color;
    if (openni::OpenNI::waitForAnyStream(&cs, 1, &idx, 5000) == openni::STATUS_OK && d.color.readFrame(&cref) == openni::STATUS_OK &&
        cref.getData() && cref.getWidth() > 0 && cref.getHeight() > 0 && cref.getStrideInBytes() >= 3 * cref.getWidth()) {
      cw = cref.getWidth();
      ch = cref.getHeight();
    }
  }
  ok = ok && send_pod(fd, cw) && send_pod(fd, ch) && (cw == 0 || send_rows(cref, 3 * std::size_t(cw)));  // RGB
  ++d.next;
  return ok;
}

[[noreturn]] void child_main(int fd, const std::string& path) {
  // Never returns into the parent's code and never runs its atexit handlers or destructors.
  try {
    auto* d = new Player();  // leaked on purpose: the driver is not torn down (see above)
    open_player(path, *d);
    const std::int32_t k = kInfo;
    if (!send_pod(fd, k) || !send_pod(fd, d->info)) ::_exit(0);
    for (;;) {
      char req = 0;
      const ssize_t r = ::recv(fd, &req, 1, 0);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0 || req != 'n') ::_exit(0);  // the parent closed the reader
      if (!send_next_frame(fd, *d)) ::_exit(0);
    }
  } catch (const std::exception& e) {
    send_error(fd, e.what());
  } catch (...) {
    send_error(fd, "unknown error in the OpenNI2 driver");
  }
  ::_exit(0);
}

std::string signal_name(int sig) {
  const char* n = ::strsignal(sig);
  return std::string(n ? n : "signal") + " (" + std::to_string(sig) + ")";
}

}  // namespace

struct OniReader::Impl {
  std::string path;
  OniInfo info;
  int fd = -1;
  pid_t child = -1;
  int next = 0;
  bool ended = false;
  static constexpr int kTimeoutMs = 60000;  // the child's own waits time out after 5 s per stream

  ~Impl() { stop(); }
  void stop() {
    if (fd >= 0) ::close(fd);
    fd = -1;
    if (child > 0) {
      ::kill(child, SIGKILL);
      int st = 0;
      while (::waitpid(child, &st, 0) < 0 && errno == EINTR) {}
      child = -1;
    }
  }
  // Reads exactly n bytes; on a closed socket or timeout throws FileError saying why (the
  // child's exit status: a crash of the driver while decoding `what`).
  void recv_all(void* buf, std::size_t n, const std::string& what) {
    char* p = static_cast<char*>(buf);
    while (n > 0) {
      pollfd pfd{fd, POLLIN, 0};
      const int pr = ::poll(&pfd, 1, kTimeoutMs);
      if (pr < 0 && errno == EINTR) continue;
      if (pr == 0) {
        stop();
        throw FileError("'" + path + "': the OpenNI2 driver stopped responding while reading " + what +
                        " (no data for 60 s); the recording may be corrupt");
      }
      const ssize_t r = ::recv(fd, p, n, 0);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) died(what);
      p += r;
      n -= std::size_t(r);
    }
  }
  [[noreturn]] void died(const std::string& what) {
    ::close(fd);
    fd = -1;
    int st = 0;
    pid_t w;
    while ((w = ::waitpid(child, &st, 0)) < 0 && errno == EINTR) {}
    child = -1;
    std::string how = "exited";
    if (w > 0 && WIFSIGNALED(st)) how = "crashed with " + signal_name(WTERMSIG(st));
    else if (w > 0 && WIFEXITED(st)) how = "exited with status " + std::to_string(WEXITSTATUS(st));
    throw FileError("'" + path + "': the OpenNI2 driver " + how + " while decoding " + what +
                    ": the recording is corrupt (" + std::to_string(next) + " frame(s) were read before it)" +
                    (next > 0 ? "; the frames before the damage replay with --last " + std::to_string(next - 1) : std::string()));
  }
  template <class T>
  T recv_pod(const std::string& what) {
    T v;
    recv_all(&v, sizeof(T), what);
    return v;
  }
  [[noreturn]] void child_error(const std::string& what) {
    const std::int32_t len = recv_pod<std::int32_t>(what);
    std::string msg(std::size_t(std::clamp(len, 0, 1 << 16)), '\0');
    recv_all(msg.data(), msg.size(), what);
    stop();
    throw FileError("'" + path + "': " + msg);
  }
};

OniReader::OniReader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw FileError("'" + path + "': no such file; check the path");
  Impl& d = *impl_;
  d.path = path;
  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) != 0)
    throw FileError("'" + path + "': cannot create a socket pair for the OpenNI2 driver process: " + std::strerror(errno));
  std::fflush(nullptr);  // nothing buffered twice
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(sv[0]);
    ::close(sv[1]);
    throw FileError("'" + path + "': cannot start the OpenNI2 driver process: " + std::strerror(errno));
  }
  if (pid == 0) {
    ::close(sv[0]);
    child_main(sv[1], path);
  }
  ::close(sv[1]);
  d.fd = sv[0];
  d.child = pid;
  const std::int32_t k = d.recv_pod<std::int32_t>("the header");
  if (k == kError) d.child_error("the header");
  if (k != kInfo) d.died("the header");
  d.info = d.recv_pod<OniInfo>("the header");
}

OniReader::~OniReader() = default;
const OniInfo& OniReader::info() const { return impl_->info; }
bool OniReader::available() { return true; }

bool OniReader::next(OniFrame& f) {
  Impl& d = *impl_;
  if (d.ended || d.fd < 0) return false;
  const std::string what = "frame " + std::to_string(d.next);
  const char req = 'n';
  if (!send_all(d.fd, &req, 1)) d.died(what);
  const std::int32_t k = d.recv_pod<std::int32_t>(what);
  if (k == kEnd) {
    d.ended = true;
    d.stop();
    return false;
  }
  if (k == kError) d.child_error(what);
  if (k != kFrame) d.died(what);
  const std::int32_t index = d.recv_pod<std::int32_t>(what), dw = d.recv_pod<std::int32_t>(what), dh = d.recv_pod<std::int32_t>(what);
  if (dw < 0 || dh < 0 || dw > 1 << 15 || dh > 1 << 15) d.died(what);
  f.depth.create(dh, dw, CV_16UC1);
  d.recv_all(f.depth.data, f.depth.total() * f.depth.elemSize(), what);
  const std::int32_t cw = d.recv_pod<std::int32_t>(what), ch = d.recv_pod<std::int32_t>(what);
  if (cw < 0 || ch < 0 || cw > 1 << 15 || ch > 1 << 15) d.died(what);
  if (cw > 0 && ch > 0) {
    cv::Mat rgb(ch, cw, CV_8UC3);
    d.recv_all(rgb.data, rgb.total() * rgb.elemSize(), what);
    cv::cvtColor(rgb, f.color, cv::COLOR_RGB2BGR);
  } else {
    f.color.release();
  }
  f.index = index;
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
