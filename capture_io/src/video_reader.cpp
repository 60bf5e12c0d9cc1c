// VideoReader: dlopen of libtbsp_video (capture_io/video_module/video_module.cpp) on first use.
#include "video_reader.h"

#include <dlfcn.h>

#include <cstdlib>
#include <filesystem>

#include "tbsp/core/error.h"

namespace tbsp {
namespace detail {

namespace {

constexpr int kVideoAbi = 1;
constexpr const char* kModuleFile = "libtbsp_video.so";

struct Module {
  int (*abi)() = nullptr;
  void* (*open)(const char*) = nullptr;
  double (*get)(void*, int) = nullptr;
  int (*grab)(void*) = nullptr;
  int (*read)(void*, cv::Mat*) = nullptr;
  void (*close)(void*) = nullptr;
  std::string error;  ///< why it could not be loaded (empty: loaded)
};

Module load_module() {
  Module m;
  std::string tried;
  for (const std::string& path : video_module_candidates()) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) {
      tried += "\n  " + path + " (no such file)";
      continue;
    }
    // RTLD_NODELETE: decoded frames and OpenCV's own state may outlive any owner here
    void* h = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
    if (!h) {
      const char* e = dlerror();
      tried += "\n  " + path + " (" + (e ? e : "cannot be loaded") + ")";
      continue;
    }
    m.abi = reinterpret_cast<int (*)()>(dlsym(h, "tbsp_video_abi_version"));
    m.open = reinterpret_cast<void* (*)(const char*)>(dlsym(h, "tbsp_video_open"));
    m.get = reinterpret_cast<double (*)(void*, int)>(dlsym(h, "tbsp_video_get"));
    m.grab = reinterpret_cast<int (*)(void*)>(dlsym(h, "tbsp_video_grab"));
    m.read = reinterpret_cast<int (*)(void*, cv::Mat*)>(dlsym(h, "tbsp_video_read"));
    m.close = reinterpret_cast<void (*)(void*)>(dlsym(h, "tbsp_video_close"));
    if (!m.abi || !m.open || !m.get || !m.grab || !m.read || !m.close || m.abi() != kVideoAbi) {
      tried += "\n  " + path + " (not tbsp's video module of this version)";
      m = Module{};
      continue;
    }
    return m;
  }
  m.error = std::string("reading video needs tbsp's video module ") + kModuleFile + " (OpenCV videoio), looked for:" + tried +
            "\nFix: reinstall tbsp (cmake --install puts it in <libdir>/tbsp/modules), or set TBSP_VIDEO_MODULE to the file.";
  return m;
}

const Module& module() {
  static const Module m = load_module();  // once per process (thread-safe initialisation)
  if (!m.error.empty()) throw FileError(m.error);
  return m;
}

}  // namespace

std::vector<std::string> video_module_candidates() {
  std::vector<std::string> out;
  // an explicit choice is the only one: a wrong path is reported, not replaced by another module
  if (const char* env = std::getenv("TBSP_VIDEO_MODULE"); env && *env) return {env};
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) out.push_back((exe.parent_path().parent_path() / "lib" / "tbsp" / "modules" / kModuleFile).string());
#ifdef TBSP_INSTALL_MODULE_DIR
  out.push_back(std::string(TBSP_INSTALL_MODULE_DIR) + "/" + kModuleFile);
#endif
#ifdef TBSP_BUILD_MODULE_DIR
  out.push_back(std::string(TBSP_BUILD_MODULE_DIR) + "/" + kModuleFile);
#endif
  return out;
}

VideoReader::~VideoReader() { close(); }

VideoReader& VideoReader::operator=(VideoReader&& o) noexcept {
  if (this != &o) {
    close();
    h_ = o.h_;
    o.h_ = nullptr;
  }
  return *this;
}

void VideoReader::close() {
  if (h_) module().close(h_);  // loaded: h_ came from it
  h_ = nullptr;
}

bool VideoReader::open(const std::string& path) {
  const Module& m = module();
  close();
  h_ = m.open(path.c_str());
  return h_ != nullptr;
}

double VideoReader::get(int prop) const { return h_ ? module().get(h_, prop) : 0.0; }

bool VideoReader::grab() { return h_ && module().grab(h_) != 0; }

bool VideoReader::read(cv::Mat& out) { return h_ && module().read(h_, &out) != 0; }

}  // namespace detail
}  // namespace tbsp
