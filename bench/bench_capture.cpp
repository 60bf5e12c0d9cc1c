// bench_capture: rasterizer and studio streaming (issue: capture_io).
//   bench_capture raster [--repeats N]      8 views of 1004x1004, depth + id + silhouette
//   bench_capture stream DIR [--frames N]   writes (if needed) and streams an 8-camera studio,
//                                           reporting resident memory along the way
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <omp.h>

#include "tbsp/core/huge_pages.h"
#include "tbsp/io/studio.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/multiview/rasterizer.h"
#include "tbsp/plugins/synth_studio.h"

using namespace tbsp;
using Clock = std::chrono::steady_clock;

namespace {
double mem_mb(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(key, 0) == 0) return std::stod(line.substr(std::strlen(key))) / 1024.0;
  return 0;
}
std::vector<Camera> ring(int k, int w, int h, const Eigen::Vector3d& target, double radius, double hfov) {
  std::vector<Camera> cams;
  for (int c = 0; c < k; ++c) {
    const double a = 2 * M_PI * c / k;
    cams.push_back(Camera::lookAt("cam" + std::to_string(c), w, h, hfov, target + Eigen::Vector3d(radius * std::sin(a), (c % 2) ? 0.8 : -0.2, radius * std::cos(a)), target, {0, 1, 0}));
  }
  return cams;
}
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

int raster(int repeats) {
  struct Case { const char* name; TriMesh mesh; std::vector<Camera> cams; };
  std::vector<Case> cases;
  cases.push_back({"icosphere, close-up (fills 53% of each view)", make_icosphere(4, 1.0), ring(8, 1004, 1004, {0, 0, 0}, 3.2, 0.75)});
  synth::Humanoid h = synth::make_humanoid(0);
  cases.push_back({"synthetic performer (detail 0), studio framing", h.mesh, ring(8, 1004, 1004, {0, 0.9, 0}, 3.6, 0.6)});
  cases.push_back({"synthetic performer (detail 1), studio framing", synth::make_humanoid(1).mesh, ring(8, 1004, 1004, {0, 0.9, 0}, 3.6, 0.6)});
  std::printf("threads: %d\n\n", omp_get_max_threads());
  std::printf("| mesh | triangles | views | buffers | median ms (all views) | ms per view | covered px per view |\n|---|---|---|---|---|---|---|\n");
  for (auto& c : cases) {
    for (int variant = 0; variant < 3; ++variant) {
      const bool bary = variant == 2, cull = variant == 1;
      RasterOptions o;
      o.barycentrics = bary;
      o.cull_backfaces = cull;
      const Rasterizer r(o);
      std::vector<double> t;
      std::vector<RenderBuffers> out;
      for (int i = 0; i < repeats; ++i) {
        const auto t0 = Clock::now();
        r.renderViews(c.mesh, c.cams, out);  // buffers re-used between frames
        t.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      }
      long covered = 0;
      for (const auto& b : out) covered += std::count(b.mask.begin(), b.mask.end(), 255);
      const double m = median(t);
      std::printf("| %s | %ld | %zu | %s | %.1f | %.2f | %ld |\n", c.name, long(c.mesh.F.rows()), c.cams.size(),
                  bary ? "depth+id+mask+barycentrics" : (cull ? "depth+id+mask, back-face culling" : "depth+id+mask"), m, m / c.cams.size(), covered / long(c.cams.size()));
    }
  }
  return 0;
}

int stream(const std::string& dir, int frames) {
  const std::string yaml = dir + "/studio.yaml";
  bool need = true;
  if (std::filesystem::exists(yaml)) need = read_studio(yaml).numFrames() != frames;
  if (need) {
    std::printf("writing a %d-frame, 8-camera 1004x1004 synthetic studio into %s ...\n", frames, dir.c_str());
    synth::StudioOptions o;
    o.frames = frames;
    o.markers = 0;
    const auto t0 = Clock::now();
    synth::write_synthetic_studio(dir, o);
    std::printf("  written in %.1f s\n", std::chrono::duration<double>(Clock::now() - t0).count());
  }
  const Studio s = read_studio(yaml);
  std::printf("\n| frames read | resident MB (VmRSS) | peak MB (VmHWM) |\n|---|---|---|\n");
  std::printf("| 0 | %.1f | %.1f |\n", mem_mb("VmRSS:"), mem_mb("VmHWM:"));
  StudioFrameStream st(s, {});
  StudioFrame fr;
  int n = 0;
  const auto t0 = Clock::now();
  double after_first = 0;
  while (st.next(fr)) {
    ++n;
    if (n == 1) after_first = mem_mb("VmRSS:");
    if (n == 1 || n == 10 || n == 25 || n == 50 || n == 75 || n == frames)
      std::printf("| %d | %.1f | %.1f |\n", n, mem_mb("VmRSS:"), mem_mb("VmHWM:"));
  }
  const double sec = std::chrono::duration<double>(Clock::now() - t0).count();
  std::printf("\n%d frames x %zu cameras (images + silhouettes) in %.2f s = %.1f frames/s; resident growth after frame 1: %.1f MB\n",
              n, s.cameras.size(), sec, n / sec, mem_mb("VmRSS:") - after_first);
  return 0;
}
}  // namespace

int main(int argc, char** argv) {
  tbsp::reexec_with_huge_pages(argv);  // as the tbsp CLI (tbsp/core/huge_pages.h)
  if (argc >= 2 && std::string(argv[1]) == "raster") {
    int repeats = 21;
    if (argc >= 4 && std::string(argv[2]) == "--repeats") repeats = std::stoi(argv[3]);
    return raster(repeats);
  }
  if (argc >= 3 && std::string(argv[1]) == "stream") {
    int frames = 100;
    if (argc >= 5 && std::string(argv[3]) == "--frames") frames = std::stoi(argv[4]);
    return stream(argv[2], frames);
  }
  std::fprintf(stderr, "usage: bench_capture raster [--repeats N] | bench_capture stream DIR [--frames N]\n");
  return 2;
}
