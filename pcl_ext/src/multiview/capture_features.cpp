#include "capture_features.h"

#include <algorithm>
#include <cmath>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"

namespace tbsp::detail {

ViewFeatures detect_features(const cv::Mat& image, const cv::Mat& silhouette, int max_features) {
  ViewFeatures out;
  cv::Mat mask = silhouette >= 128;
  const cv::Rect box = cv::boundingRect(mask);
  if (box.area() == 0) return out;
  const int m = 8;
  const cv::Rect roi = (box + cv::Point(-m, -m) + cv::Size(2 * m, 2 * m)) & cv::Rect(0, 0, image.cols, image.rows);
  cv::Mat gray;
  if (image.channels() == 3) cv::cvtColor(image(roi), gray, cv::COLOR_BGR2GRAY);
  else gray = image(roi);
  std::vector<cv::KeyPoint> kp;
  cv::Ptr<cv::SIFT> sift = cv::SIFT::create(max_features);
  sift->detectAndCompute(gray, mask(roi), kp, out.desc);
  out.pixel.reserve(kp.size());
  for (const cv::KeyPoint& k : kp) out.pixel.emplace_back(k.pt.x + roi.x, k.pt.y + roi.y);
  return out;
}

bool smooth_depth(const RenderBuffers& b, int x, int y) {
  const int r = 2;
  if (x < r || y < r || x >= b.width - r || y >= b.height - r) return false;
  const float d0 = b.depth[std::size_t(y) * std::size_t(b.width) + std::size_t(x)];
  for (int dy = -r; dy <= r; dy += r)
    for (int dx = -r; dx <= r; dx += r) {
      const float d = b.depth[std::size_t(y + dy) * std::size_t(b.width) + std::size_t(x + dx)];
      if (!std::isfinite(d) || std::abs(d - d0) >= 0.01f * d0) return false;
    }
  return true;
}

LiftedFeatures lift_features(const ViewFeatures& f, const RenderBuffers& b, const std::vector<FeatureMatch>& inherit, const TriMesh* mesh,
                             const Camera* cam, double inherit_px) {
  if (b.bary.empty() && !(mesh && cam))
    throw InvalidInput("[tbsp::detail::lift_features] buffers rendered without barycentrics need the mesh and the camera");
  LiftedFeatures out;
  std::vector<int> rows;
  std::vector<const FeatureMatch*> track(f.pixel.size(), nullptr);
  if (mesh && cam)
    for (const FeatureMatch& m : inherit)
      if (m.keypoint >= 0 && std::size_t(m.keypoint) < track.size()) track[std::size_t(m.keypoint)] = &m;
  auto at = [&](int x, int y) { return static_cast<std::size_t>(y) * b.width + x; };
  for (std::size_t i = 0; i < f.pixel.size(); ++i) {
    const int x = static_cast<int>(std::lround(f.pixel[i].x())), y = static_cast<int>(std::lround(f.pixel[i].y()));
    if (x < 0 || y < 0 || x >= b.width || y >= b.height) continue;
    const std::int32_t face = b.face[at(x, y)];
    if (face < 0 || !smooth_depth(b, x, y)) continue;
    const FeatureMatch* t = track[i];
    if (t && (cam->project(surface_point(*mesh, t->face, t->bary)) - f.pixel[i]).norm() <= inherit_px) {
      out.face.push_back(t->face);  // the track keeps its surface point
      out.bary.push_back(t->bary);
    } else if (mesh && cam) {  // the surface point under the keypoint itself, not under its pixel's centre
      out.face.push_back(face);
      out.bary.push_back(point_barycentrics(*mesh, *cam, face, f.pixel[i]));
    } else {
      const float b1 = b.bary[2 * at(x, y)], b2 = b.bary[2 * at(x, y) + 1];
      out.face.push_back(face);
      out.bary.emplace_back(1.0 - b1 - b2, b1, b2);
    }
    rows.push_back(static_cast<int>(i));
  }
  out.desc.create(static_cast<int>(rows.size()), f.desc.cols, CV_32F);
  for (std::size_t r = 0; r < rows.size(); ++r) f.desc.row(rows[r]).copyTo(out.desc.row(static_cast<int>(r)));
  return out;
}

int match_features(const LiftedFeatures& from, const ViewFeatures& to, const TriMesh& mesh, const Camera& cam, double ratio,
                   double max_flow_px, std::vector<FeatureMatch>& out) {
  if (from.desc.rows < 1 || to.desc.rows < 2) return 0;
  cv::BFMatcher matcher(cv::NORM_L2);
  std::vector<std::vector<cv::DMatch>> knn;
  matcher.knnMatch(from.desc, to.desc, knn, 2);
  // best match per target keypoint (one-to-one)
  std::vector<int> owner(to.pixel.size(), -1);
  std::vector<float> best(to.pixel.size(), 0.f);
  std::vector<Eigen::Vector2d> predicted(knn.size());
  for (std::size_t i = 0; i < knn.size(); ++i) {
    if (knn[i].size() < 2 || knn[i][0].distance > ratio * knn[i][1].distance) continue;
    const int j = knn[i][0].trainIdx;
    const Eigen::Vector3d X = surface_point(mesh, from.face[i], from.bary[i]);
    if (!(cam.depth(X) > 0)) continue;
    predicted[i] = cam.project(X);
    if ((predicted[i] - to.pixel[std::size_t(j)]).norm() > max_flow_px) continue;
    if (owner[std::size_t(j)] < 0 || knn[i][0].distance < best[std::size_t(j)]) {
      owner[std::size_t(j)] = static_cast<int>(i);
      best[std::size_t(j)] = knn[i][0].distance;
    }
  }
  std::vector<std::size_t> js;
  for (std::size_t j = 0; j < owner.size(); ++j)
    if (owner[j] >= 0) js.push_back(j);
  // local consistency of the image motion
  std::vector<Eigen::Vector2d> flow(js.size());
  for (std::size_t a = 0; a < js.size(); ++a) flow[a] = to.pixel[js[a]] - predicted[std::size_t(owner[js[a]])];
  int n = 0;
  std::vector<std::pair<double, std::size_t>> near;
  std::vector<double> fx, fy;
  for (std::size_t a = 0; a < js.size(); ++a) {
    near.clear();
    for (std::size_t c = 0; c < js.size(); ++c)
      if (c != a) near.emplace_back((to.pixel[js[c]] - to.pixel[js[a]]).squaredNorm(), c);
    const std::size_t k = std::min<std::size_t>(8, near.size());
    if (k >= 3) {
      std::partial_sort(near.begin(), near.begin() + long(k), near.end());
      fx.clear();
      fy.clear();
      for (std::size_t q = 0; q < k; ++q) {
        fx.push_back(flow[near[q].second].x());
        fy.push_back(flow[near[q].second].y());
      }
      std::nth_element(fx.begin(), fx.begin() + long(k / 2), fx.end());
      std::nth_element(fy.begin(), fy.begin() + long(k / 2), fy.end());
      const Eigen::Vector2d med(fx[k / 2], fy[k / 2]);
      if ((flow[a] - med).norm() > 3.0 + 0.25 * med.norm()) continue;
    }
    const std::size_t i = std::size_t(owner[js[a]]);
    out.push_back({from.face[i], from.bary[i], to.pixel[js[a]], int(js[a])});
    ++n;
  }
  return n;
}

LiftedFeatures facing_features(const std::vector<LiftedFeatures>& sets, const TriMesh& mesh, const Camera& cam, double min_cos) {
  LiftedFeatures out;
  std::vector<std::pair<std::size_t, int>> keep;
  const Eigen::Vector3d C = cam.center();
  for (std::size_t s = 0; s < sets.size(); ++s)
    for (std::size_t i = 0; i < sets[s].face.size(); ++i) {
      const int f = sets[s].face[i];
      const Eigen::Vector3d a = mesh.V.row(mesh.F(f, 0)).transpose(), b = mesh.V.row(mesh.F(f, 1)).transpose(),
                            c = mesh.V.row(mesh.F(f, 2)).transpose();
      const Eigen::Vector3d nrm = (b - a).cross(c - a);
      const Eigen::Vector3d to_cam = C - surface_point(mesh, f, sets[s].bary[i]);
      const double d = nrm.norm() * to_cam.norm();
      if (d > 0 && nrm.dot(to_cam) >= min_cos * d) keep.emplace_back(s, int(i));
    }
  if (keep.empty()) return out;
  out.desc.create(int(keep.size()), sets[keep.front().first].desc.cols, CV_32F);
  for (std::size_t r = 0; r < keep.size(); ++r) {
    const auto& st = sets[keep[r].first];
    out.face.push_back(st.face[std::size_t(keep[r].second)]);
    out.bary.push_back(st.bary[std::size_t(keep[r].second)]);
    st.desc.row(keep[r].second).copyTo(out.desc.row(int(r)));
  }
  return out;
}

}  // namespace tbsp::detail
