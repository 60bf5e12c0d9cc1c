#include "studio_frames.h"

#include <filesystem>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/multiview/rasterizer.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

std::pair<int, int> parse_frames(const std::string& s, const Studio& st, const std::string& option) {
  if (s.empty()) return {st.first_frame, st.last_frame};
  int a = 0, b = 0;
  char c = 0;
  std::istringstream is(s);
  if (!(is >> a)) throw InvalidInput(option + " '" + s + "': expected a or a:b (frame numbers)");
  b = a;
  if (is >> c) {
    if (c != ':' || !(is >> b)) throw InvalidInput(option + " '" + s + "': expected a or a:b (frame numbers)");
  }
  if (a > b || a < st.first_frame || b > st.last_frame)
    throw InvalidInput(option + " " + s + " is outside the studio's frames " + std::to_string(st.first_frame) + ".." + std::to_string(st.last_frame));
  return {a, b};
}

int for_each_frame(const Studio& st, int first, int last, bool silhouettes, bool quiet,
                   const std::function<void(const StudioFrame&, const ProgressCallback&, ProgressBar&)>& run) {
  StudioFrameStream::Options so;
  so.first = first;
  so.last = last;
  so.silhouettes = silhouettes;
  StudioFrameStream stream(st, so);
  ProgressBar bar(!quiet);
  const ProgressCallback cb = bar.callback();
  StudioFrame fr;
  const int total = last - first + 1;
  int done = 0;
  while (stream.next(fr)) {
    const int base = done;
    const ProgressCallback frame_cb = [&](double x, const std::string& stage) {
      return !cb || cb((base + x) / total, "frame " + std::to_string(fr.frame) + ": " + stage);
    };
    run(fr, frame_cb, bar);
    ++done;
  }
  return done;
}

void write_png(const std::string& path, const cv::Mat& m) {
  atomic_write_with(path, [&](const std::string& tmp) {
    const std::string t = tmp + ".png";
    if (!cv::imwrite(t, m)) return false;
    fs::rename(t, tmp);
    return true;
  });
}

// All views of one frame in a grid, each cropped to the performer: where mesh and silhouette
// agree the camera image is tinted green; mesh outside the silhouette is blue, silhouette the
// mesh misses is red.
cv::Mat overlay_grid(const TriMesh& mesh, const std::vector<Camera>& cams, const StudioFrame& fr) {
  RasterOptions ro;
  ro.barycentrics = false;
  const std::vector<RenderBuffers> buf = Rasterizer(ro).renderViews(mesh, cams);
  const int n = int(cams.size()), cols = std::min(n, 4), rows = (n + cols - 1) / cols;
  const int w = 300, h = 400;
  cv::Mat grid(rows * h, cols * w, CV_8UC3, cv::Scalar(40, 40, 40));
  for (int k = 0; k < n; ++k) {
    const Camera& cam = cams[std::size_t(k)];
    cv::Mat img;
    const cv::Mat& src = fr.images[std::size_t(k)];
    if (src.empty()) img = cv::Mat(cam.height(), cam.width(), CV_8UC3, cv::Scalar(0, 0, 0));
    else if (src.channels() == 1) cv::cvtColor(src, img, cv::COLOR_GRAY2BGR);
    else img = src.clone();
    const RenderBuffers& b = buf[std::size_t(k)];
    const cv::Mat& sil = fr.silhouettes[std::size_t(k)];
    // The crop: the mesh's box, and the silhouette near it (within a quarter of the box's size:
    // segmentation specks elsewhere in the image do not shrink the performer to a dot).
    cv::Rect mesh_box, sil_box;
    for (int y = 0; y < img.rows; ++y)
      for (int x = 0; x < img.cols; ++x)
        if (b.mask[std::size_t(y) * b.width + x] != 0) mesh_box |= cv::Rect(x, y, 1, 1);
    const cv::Rect near = mesh_box.area() == 0 ? cv::Rect(0, 0, img.cols, img.rows)
                                               : cv::Rect(mesh_box.x - mesh_box.width / 4, mesh_box.y - mesh_box.height / 4,
                                                          mesh_box.width * 3 / 2, mesh_box.height * 3 / 2);
    for (int y = 0; y < img.rows; ++y)
      for (int x = 0; x < img.cols; ++x) {
        const bool m = b.mask[std::size_t(y) * b.width + x] != 0, s = sil.at<uchar>(y, x) >= 128;
        if (!m && !s) continue;
        if (s && near.contains(cv::Point(x, y))) sil_box |= cv::Rect(x, y, 1, 1);
        cv::Vec3b& p = img.at<cv::Vec3b>(y, x);
        if (m && s) p = cv::Vec3b(uchar(p[0] * 0.7), uchar(p[1] * 0.7 + 60), uchar(p[2] * 0.7));
        else p = m ? cv::Vec3b(255, 80, 0) : cv::Vec3b(0, 0, 255);
      }
    cv::Rect box = mesh_box | sil_box;
    if (box.area() == 0) box = cv::Rect(0, 0, img.cols, img.rows);
    // crop with the panel's aspect ratio around the performer, 8 % margin
    const double bw = box.width * 1.16, bh = box.height * 1.16, scale = std::max(bw / w, bh / h);
    const cv::Point2d c(box.x + box.width / 2.0, box.y + box.height / 2.0);
    const cv::Rect crop = cv::Rect(int(c.x - scale * w / 2), int(c.y - scale * h / 2), int(scale * w), int(scale * h)) & cv::Rect(0, 0, img.cols, img.rows);
    cv::Mat panel(h, w, CV_8UC3, cv::Scalar(40, 40, 40)), small;
    const double f = std::min(double(w) / crop.width, double(h) / crop.height);
    cv::resize(img(crop), small, cv::Size(std::max(1, int(crop.width * f)), std::max(1, int(crop.height * f))), 0, 0, cv::INTER_AREA);
    small.copyTo(panel(cv::Rect((w - small.cols) / 2, (h - small.rows) / 2, small.cols, small.rows)));
    cv::putText(panel, cam.name(), cv::Point(6, 18), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1);
    panel.copyTo(grid(cv::Rect((k % cols) * w, (k / cols) * h, w, h)));
  }
  return grid;
}

}  // namespace tbsp::cli
