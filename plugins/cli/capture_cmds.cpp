#include "capture_cmds.h"

#include "command.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include <pcl/conversions.h>

#include "progress_bar.h"
#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/depth_io.h"
#include "tbsp/io/studio.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {
double peak_rss_mb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  return 0;
}
template <typename PointT>
void save_cloud(const std::string& path, const pcl::PointCloud<PointT>& c) {
  pcl::PCLPointCloud2 b;
  pcl::toPCLPointCloud2(c, b);
  write_cloud(path, b, true);
}
}  // namespace

void add_synth_studio(CLI::App& app, SynthStudioArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("synth-studio", "render a synthetic multi-view studio with ground truth (docs/studio_format.md)");
  sub->add_option("--out", a.out, "output folder (studio.yaml, images, silhouettes, gt meshes, markers.trc)")->required();
  sub->add_option("--cameras", a.o.cameras, "number of cameras (default 8)");
  sub->add_option("--width", a.o.width, "image width (default 1004)");
  sub->add_option("--height", a.o.height, "image height (default 1004)");
  sub->add_option("--frames", a.o.frames, "number of frames (default 10)");
  sub->add_option("--fps", a.o.frame_rate, "frame rate (default 25)");
  sub->add_option("--image-noise", a.o.image_noise, "Gaussian image noise in grey levels (default 0)");
  sub->add_option("--markers", a.o.markers, "marker vertices written to markers.trc (default 12)");
  sub->add_flag("--range-scans", a.o.range_scans, "also write a virtual range scan per camera and frame (scans/camK/FFFF.pcd)");
  sub->add_flag("--depth-images", a.o.depth_images,
                "also write the range scans as 16-bit depth images (depth/camK/FFFF.png, 0.2 mm units; intrinsics = camera's / --scan-stride)");
  sub->add_option("--scan-noise", a.o.scan_noise, "range-scan noise along the rays, metres (default 0.002)");
  sub->add_option("--scan-stride", a.o.scan_stride, "range-scan pixel stride (default 2)");
  sub->add_option("--detail", a.o.detail, "performer mesh resolution 0..3 (default 1)");
  sub->add_option("--folds", a.o.folds, "amplitude of cloth folds on skirt, torso and sleeves, metres (default 0 = none; use with --detail 2)");
  sub->add_option("--seed", a.o.seed, "random seed");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar or summary");
}

int cmd_synth_studio(const SynthStudioArgs& a) {
  const auto t0 = Clock::now();
  ProgressBar bar(!a.quiet);
  const auto r = synth::write_synthetic_studio(a.out, a.o, bar.callback());
  bar.finish();
  const double s = seconds_since(t0);
  if (!a.quiet)
    std::cout << "synthetic studio: " << a.o.cameras << " cameras " << a.o.width << "x" << a.o.height << ", " << a.o.frames
              << " frames, performer " << r.vertices << " vertices / " << r.faces << " faces; " << r.images_written
              << " images in " << s << " s\n  wrote " << r.studio.path << "\n";
  return 0;
}

void add_replay(CLI::App& app, ReplayArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("replay", "replay a recording: an OpenNI2 .oni file, a folder of 16-bit depth images, or a studio dataset");
  sub->add_option("input", a.input, ".oni file, depth-image folder, studio.yaml or a folder holding one")->required();
  sub->add_option("--out", a.out, "write one cloud per frame into this folder (cloud_FFFF.pcd/.ply)");
  sub->add_option("--format", a.format, "pcd (default) or ply")->check(CLI::IsMember({"pcd", "ply"}));
  sub->add_option("--first", a.first, "first frame (0-based for recordings; studio frame numbers for studios)");
  sub->add_option("--last", a.last, "last frame (inclusive)");
  sub->add_option("--intrinsics", a.intrinsics, "fx,fy,cx,cy of a depth-image folder");
  sub->add_option("--depth-scale", a.depth_scale, "metres per raw depth unit of a depth-image folder (default 0.001)");
  sub->add_flag("--check", a.check_only, "studio: only check the files (list missing frames) without streaming");
}

int cmd_replay(const ReplayArgs& a) {
  const fs::path in(a.input);
  std::error_code ec;
  if (!fs::exists(in, ec)) throw FileError("'" + a.input + "': no such file or folder");
  if (a.last >= 0 && a.first > a.last)
    throw InvalidInput("--first " + std::to_string(a.first) + " is after --last " + std::to_string(a.last) + "; no frame would be replayed");
  if (!a.out.empty()) fs::create_directories(a.out, ec);
  auto out_path = [&](int i) {
    return (fs::path(a.out) / ("cloud_" + expand_frame_pattern("%04d", i) + "." + a.format)).string();
  };
  const auto t0 = Clock::now();
  auto elapsed = [&] { return seconds_since(t0); };

  // Studio dataset.
  const bool is_yaml = in.extension() == ".yaml" || in.extension() == ".yml";
  if (is_yaml || (fs::is_directory(in) && fs::exists(in / "studio.yaml"))) {
    const Studio s = read_studio(a.input);
    std::cout << "studio '" << s.name << "': " << s.cameras.size() << " cameras, frames " << s.first_frame << ".." << s.last_frame
              << " at " << s.frame_rate << " fps\n";
    for (const auto& c : s.cameras) {
      const Eigen::Vector3d C = c.camera.center();
      std::cout << "  " << c.camera.name() << ": " << c.camera.width() << "x" << c.camera.height() << ", f = " << c.camera.K()(0, 0)
                << " px, centre (" << C.x() << ", " << C.y() << ", " << C.z() << ")"
                << (c.images.empty() ? (c.video.empty() ? "" : ", video " + c.video) : ", images " + c.images)
                << (c.silhouettes.empty() ? "" : ", silhouettes " + c.silhouettes) << "\n";
    }
    for (const auto& [what, f] : {std::pair<const char*, std::string>{"template", s.template_mesh}, {"markers", s.markers},
                                  {"skeleton", s.skeleton}, {"ground truth", s.ground_truth}})
      if (!f.empty()) std::cout << "  " << what << ": " << f << "\n";
    const StudioCheck chk = check_studio(s);
    std::cout << "check: " << chk.summary() << "\n";
    if (!chk.ok()) return 2;
    if (a.check_only) return 0;
    StudioFrameStream::Options so;
    so.first = a.first;
    so.last = a.last;
    StudioFrameStream stream(s, so);
    StudioFrame fr;
    int n = 0;
    while (stream.next(fr)) {
      double fg = 0;
      int ns = 0;
      for (const auto& m : fr.silhouettes)
        if (!m.empty()) { fg += cv::countNonZero(m) / double(m.total()); ++ns; }
      std::cout << "  frame " << fr.frame << ": " << fr.images.size() << " views read"
                << (ns ? ", mean silhouette coverage " + std::to_string(100.0 * fg / ns).substr(0, 5) + " %" : std::string()) << "\n";
      ++n;
    }
    std::cout << n << " frames streamed in " << elapsed() << " s, peak memory " << peak_rss_mb() << " MB\n";
    return 0;
  }

  // OpenNI2 recording.
  if (in.extension() == ".oni") {
    OniReader r(a.input);
    const OniInfo& i = r.info();
    std::cout << a.input << ": depth " << i.depth_width << "x" << i.depth_height << " (" << i.depth_frames << " frames, "
              << i.depth_scale * 1000 << " mm units, fx " << i.depth_intrinsics.fx << " fy " << i.depth_intrinsics.fy << ")";
    if (i.has_color) std::cout << ", colour " << i.color_width << "x" << i.color_height << " (" << i.color_frames << " frames)";
    std::cout << ", " << i.fps << " fps\n";
    OniFrame f;
    int n = 0;
    while (r.next(f)) {
      if (f.index < a.first || (a.last >= 0 && f.index > a.last)) continue;
      int valid = 0;
      if (!f.color.empty() && f.color.size() == f.depth.size()) {
        const auto c = depth_to_cloud(f.depth, f.color, i.depth_intrinsics, i.depth_scale);
        for (const auto& p : c) valid += std::isfinite(p.z);
        if (!a.out.empty()) save_cloud(out_path(f.index), c);
      } else {
        const auto c = depth_to_cloud(f.depth, i.depth_intrinsics, i.depth_scale);
        for (const auto& p : c) valid += std::isfinite(p.z);
        if (!a.out.empty()) save_cloud(out_path(f.index), c);
      }
      std::cout << "  frame " << f.index << ": " << valid << " valid points" << (f.color.empty() ? "" : " + colour") << "\n";
      ++n;
    }
    std::cout << n << " frames replayed in " << elapsed() << " s" << (a.out.empty() ? "" : ", clouds in " + a.out) << "\n";
    return 0;
  }

  // Folder of depth images.
  if (fs::is_directory(in)) {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(in)) {
      const std::string ext = e.path().extension().string();
      if (ext == ".png" || ext == ".pgm" || ext == ".tif" || ext == ".tiff") files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    if (files.empty()) throw FileError("'" + a.input + "': no studio.yaml and no depth images (.png .pgm .tif .tiff) in this folder");
    DepthIntrinsics K;
    char c1, c2, c3;
    std::istringstream is(a.intrinsics);
    if (a.intrinsics.empty())
      throw InvalidInput("a depth-image folder needs --intrinsics fx,fy,cx,cy (pixels), e.g. --intrinsics 525,525,319.5,239.5");
    std::string rest;
    if (!(is >> K.fx >> c1 >> K.fy >> c2 >> K.cx >> c3 >> K.cy) || c1 != ',' || c2 != ',' || c3 != ',' || (is >> rest))
      throw InvalidInput("--intrinsics '" + a.intrinsics + "': expected four numbers fx,fy,cx,cy (pixels), e.g. 525,525,319.5,239.5");
    if (a.first >= static_cast<int>(files.size()))
      throw InvalidInput("--first " + std::to_string(a.first) + " is beyond the " + std::to_string(files.size()) + " depth images of '" +
                         a.input + "' (frames 0.." + std::to_string(files.size() - 1) + ")");
    std::cout << a.input << ": " << files.size() << " depth images\n";
    int n = 0;
    for (std::size_t k = 0; k < files.size(); ++k) {
      const int idx = static_cast<int>(k);
      if (idx < a.first || (a.last >= 0 && idx > a.last)) continue;
      const cv::Mat d = read_depth_image(files[k].string());
      const auto c = depth_to_cloud(d, K, a.depth_scale);
      int valid = 0;
      for (const auto& p : c) valid += std::isfinite(p.z);
      if (!a.out.empty()) save_cloud(out_path(idx), c);
      std::cout << "  " << files[k].filename().string() << ": " << valid << " valid points\n";
      ++n;
    }
    std::cout << n << " frames converted in " << elapsed() << " s" << (a.out.empty() ? "" : ", clouds in " + a.out) << "\n";
    return 0;
  }
  throw InvalidInput("'" + a.input + "': not a studio (.yaml), an .oni recording or a folder of depth images");
}

void add_capture_commands(CLI::App& app, CommandTable& table) {
  register_command<SynthStudioArgs>(app, table, add_synth_studio, cmd_synth_studio);
  register_command<ReplayArgs>(app, table, add_replay, cmd_replay);
}

}  // namespace tbsp::cli
