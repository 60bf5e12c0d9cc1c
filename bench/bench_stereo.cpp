// bench_stereo: stereo depth and multi-view fusion (docs/stereo.md).
//   bench_stereo [--repeats N] [--studio DIR]
// 1. Middlebury pairs: tbsp compute_disparity (dense) against one raw OpenCV StereoSGBM pass
//    (3-way, same range) on the same images: time ratio and bad-pixel rates.
// 2. One 8-view 1004x1004 studio frame (synthetic, written to DIR or a temp folder): fusion time
//    (median of N), points, points per second, peak RSS, and raw SGBM over the same pairs'
//    sizes and ranges (one pass each, no left-right check, no fusion) in the same run.
// 3. Model-guided refinement of the studio's performer at detail 2 (17k vertices) with 1 cm
//    folds, smoothed by 20 umbrella steps: stereo search + fit time (median of N).
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bench_util.h"
#include "tbsp/core/huge_pages.h"
#include "tbsp/io/studio.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/topology.h"
#include "tbsp/multiview/model_guided_stereo.h"
#include "tbsp/multiview/stereo_depth_fusion.h"
#include "tbsp/plugins/synth_studio.h"

using namespace tbsp;
using namespace tbsp::bench;
namespace fs = std::filesystem;

namespace {
double raw_sgbm_seconds(const cv::Mat& L, const cv::Mat& R, int min_d, int num, int repeats) {
  auto m = cv::StereoSGBM::create(min_d, num, 5, 8 * 3 * 25, 32 * 3 * 25, -1, 63, 5, 0, 0, cv::StereoSGBM::MODE_SGBM_3WAY);
  std::vector<double> t;
  cv::Mat d;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = Clock::now();
    m->compute(L, R, d);
    t.push_back(since(t0));
  }
  return median(t);
}
}  // namespace

int main(int argc, char** argv) {
  tbsp::reexec_with_huge_pages(argv);
  int repeats = 3;
  std::string studio_dir;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--repeats") && i + 1 < argc) repeats = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--studio") && i + 1 < argc) studio_dir = argv[++i];
    else {
      std::fprintf(stderr, "usage: bench_stereo [--repeats N] [--studio DIR]\n");
      return 2;
    }
  }

  std::printf("## Middlebury pairs (median of %d)\n\n", repeats);
  std::printf("| scene | size | disparities | tbsp (s) | raw SGBM 1 pass (s) | ratio | tbsp bad > 1 px | raw SGBM bad > 1 px |\n|---|---|---|---|---|---|---|---|\n");
  struct Scene {
    const char *name, *l, *r, *g;
    double s;
    int nd;
  };
  const Scene scenes[] = {{"tsukuba", "im3.png", "im4.png", "disp3.pgm", 16, 16},
                          {"venus", "im2.png", "im6.png", "disp2.pgm", 8, 32},
                          {"teddy", "im2.png", "im6.png", "disp2.png", 4, 64},
                          {"cones", "im2.png", "im6.png", "disp2.png", 4, 64}};
  for (const Scene& s : scenes) {
    const std::string dir = std::string(TBSP_SHARED_DATA_DIR) + "/capture/fjordyo0707__StereoMatching-CostFilter/testdata/" + s.name + "/";
    const cv::Mat L = cv::imread(dir + s.l), R = cv::imread(dir + s.r), G = cv::imread(dir + s.g, cv::IMREAD_GRAYSCALE);
    if (L.empty() || R.empty() || G.empty()) {
      std::printf("| %s | missing (%s) | | | | | | |\n", s.name, dir.c_str());
      continue;
    }
    StereoMatchOptions o;
    o.num_disparities = s.nd;
    o.fill_invalid = true;
    std::vector<double> t;
    DisparityMap d;
    for (int r = 0; r < repeats; ++r) {
      const auto t0 = Clock::now();
      d = compute_disparity(L, R, o);
      t.push_back(since(t0));
    }
    auto raw = cv::StereoSGBM::create(0, s.nd, 5, 8 * 3 * 25, 32 * 3 * 25, -1, 63, 5, 0, 0, cv::StereoSGBM::MODE_SGBM_3WAY);
    cv::Mat r16, rd;
    raw->compute(L, R, r16);
    r16.convertTo(rd, CV_32F, 1.0 / 16);
    rd.setTo(NAN, r16 < 0);
    const double traw = raw_sgbm_seconds(L, R, 0, s.nd, repeats);
    std::printf("| %s | %dx%d | %d | %.3f | %.3f | %.1f | %.2f %% | %.2f %% |\n", s.name, L.cols, L.rows, s.nd, median(t), traw, median(t) / traw,
                bad_pixel_rate(d.disparity, G, s.s), bad_pixel_rate(rd, G, s.s));
  }

  // Studio frame.
  // Rendered afresh each run (a cached studio would outlive a change of the renderer) unless
  // --studio names one.
  const fs::path tmp_root = fs::temp_directory_path() / ("tbsp_bench_stereo_" + std::to_string(::getpid()));
  fs::path dir = studio_dir.empty() ? tmp_root / "studio" : fs::path(studio_dir);
  if (!fs::exists(dir / "studio.yaml")) {
    synth::StudioOptions so;
    so.frames = 1;
    so.markers = 4;
    synth::write_synthetic_studio(dir.string(), so);
  }
  const Studio st = read_studio((dir / "studio.yaml").string());
  StudioFrameStream stream(st, {});
  StudioFrame fr;
  if (!stream.next(fr)) return 1;
  const auto cams = st.cameraList();
  StereoDepthFusion<pcl::PointXYZRGBNormal> fusion;
  std::vector<double> t, tm, tf;
  pcl::PointCloud<pcl::PointXYZRGBNormal> cloud;
  for (int r = 0; r < repeats; ++r) {
    fusion.setInputFrame(cams, fr.images, fr.silhouettes, fr.frame);
    fusion.compute(cloud);
    t.push_back(fusion.report().seconds_total);
    tm.push_back(fusion.report().seconds_match);
    tf.push_back(fusion.report().seconds_fusion);
  }
  // Raw SGBM over the same pairs: the images at the same scale, each pair's range, one pass.
  double traw = 0;
  const double s = fusion.options().image_scale;
  for (std::size_t k = 0; k + 1 < fusion.getDepthMaps().size(); k += 2) {
    const ViewDepth& v = fusion.getDepthMaps()[k];
    cv::Mat a, b;
    cv::resize(fr.images[v.camera], a, cv::Size(), s, s, cv::INTER_AREA);
    cv::resize(fr.images[v.partner], b, cv::Size(), s, s, cv::INTER_AREA);
    traw += raw_sgbm_seconds(a, b, v.disparity_min, v.disparity_count, repeats);
  }
  std::printf("\n## Studio frame: %zu views of %dx%d, scale %.2f (median of %d)\n\n", cams.size(), cams[0].width(), cams[0].height(), s, repeats);
  std::printf("| pairs | points | tbsp depth maps + fusion (s) | of which matching (s) | fusion (s) | points/s | raw SGBM, same pairs, 1 pass (s) | ratio | peak RSS (MB) |\n|---|---|---|---|---|---|---|---|---|\n");
  std::printf("| %d | %zu | %.2f | %.2f | %.2f | %.0f | %.2f | %.1f | %.0f |\n", fusion.report().pairs, cloud.size(), median(t), median(tm), median(tf),
              cloud.size() / median(t), traw, median(t) / traw, peak_rss_mb());

  // Model-guided refinement.
  const fs::path dir2 = tmp_root / "studio_detail2_folds";
  {
    synth::StudioOptions so;
    so.frames = 1;
    so.markers = 4;
    so.detail = 2;
    so.folds = 0.01;  // as in ModelGuidedStereo.SmoothedOffsetMeshRecoversTheGroundTruth
    synth::write_synthetic_studio(dir2.string(), so);
  }
  const Studio st2 = read_studio((dir2 / "studio.yaml").string());
  StudioFrameStream stream2(st2, {});
  StudioFrame fr2;
  if (!stream2.next(fr2)) return 1;
  TriMesh mesh = read_mesh(st2.groundTruthPath(fr2.frame));
  {  // 20 umbrella smoothing steps, as in the test
    const auto adj = vertex_adjacency(mesh.F, mesh.V.rows());
    const std::vector<char> all(std::size_t(mesh.V.rows()), 1);
    for (int it = 0; it < 20; ++it) umbrella_step(mesh.V, adj, all, 0.5);
  }
  ModelGuidedStereo mvs;
  std::vector<double> ts, tfit;
  long pts = 0;
  for (int r = 0; r < repeats; ++r) {
    mvs.setInputFrame(st2.cameraList(), fr2.images, fr2.silhouettes, fr2.frame);
    mvs.setInputMesh(mesh);
    TriMesh out;
    mvs.refine(out);
    ts.push_back(mvs.report().seconds_stereo);
    tfit.push_back(mvs.report().seconds_fit);
    pts = mvs.report().points;
  }
  std::printf("\n## Model-guided refinement (median of %d)\n\n| vertices | searched pixels | points | stereo (s) | fit (s) | total (s) | peak RSS (MB) |\n|---|---|---|---|---|---|---|\n", repeats);
  std::printf("| %ld | %ld | %ld | %.2f | %.2f | %.2f | %.0f |\n", long(mesh.V.rows()), mvs.report().samples, pts, median(ts), median(tfit),
              median(ts) + median(tfit), peak_rss_mb());
  std::error_code ec;
  fs::remove_all(tmp_root, ec);
  return 0;
}
