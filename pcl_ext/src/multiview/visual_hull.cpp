#include "tbsp/multiview/visual_hull.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/multiview/rasterizer.h"
#include "silhouette_match.h"

namespace tbsp {

bool VisualHullOptions::isValid(std::string* why) const {
  auto fail = [&](const char* m) {
    if (why) *why = m;
    return false;
  };
  if (resolution < 16 || resolution > 1024) return fail("resolution must be in 16..1024");
  if (margin_px < 0 || margin_px > 50) return fail("margin_px must be in 0..50");
  if (!box.isEmpty() && (!box.min().allFinite() || !box.max().allFinite() || (box.max() - box.min()).minCoeff() <= 0))
    return fail("box must be empty (automatic) or finite with a positive extent along every axis");
  return true;
}

std::size_t VisualHull::occupiedCount() const {
  return std::size_t(std::count(occupied.begin(), occupied.end(), std::uint8_t(1)));
}

namespace {

struct View {
  const Camera* cam = nullptr;
  cv::Mat mask;     // CV_8U, 255 foreground (dilated by the margin)
  cv::Mat dist_fg;  // CV_32F: distance of each pixel to the nearest foreground pixel

  bool inside(const Eigen::Vector3d& X) const {
    if (!(cam->depth(X) > 0)) return false;
    const Eigen::Vector2d p = cam->project(X);
    if (!p.allFinite() || !cam->inImage(p)) return false;
    const int x = int(std::lround(p.x())), y = int(std::lround(p.y()));
    return mask.at<std::uint8_t>(std::clamp(y, 0, mask.rows - 1), std::clamp(x, 0, mask.cols - 1)) != 0;
  }

  // Conservative: false only when no point of the ball (c, r) can project onto the foreground.
  bool ballMayBeInside(const Eigen::Vector3d& c, double r) const {
    const double z = cam->depth(c);
    if (z < -r) return false;          // wholly behind the camera: never projects
    if (!(z > 1.01 * r)) return true;  // the ball reaches the camera plane: undecided
    const Eigen::Vector2d p = cam->project(c);
    if (!p.allFinite()) return true;
    // image radius of the ball (pinhole bound, with room for lens distortion and rounding)
    const double rho = 1.25 * std::max(cam->K()(0, 0), cam->K()(1, 1)) * r / (z - r) + 2.0;
    const double cx = std::clamp(p.x(), 0.0, double(mask.cols - 1)), cy = std::clamp(p.y(), 0.0, double(mask.rows - 1));
    const double off = std::hypot(p.x() - cx, p.y() - cy);  // outside the image by this much
    if (off > rho) return false;
    const float d = dist_fg.at<float>(int(std::lround(cy)), int(std::lround(cx)));
    return double(d) - off <= rho;
  }
};

bool inside_all(const std::vector<View>& views, const Eigen::Vector3d& X) {
  for (const View& v : views)
    if (!v.inside(X)) return false;
  return true;
}

// Conservative carving of `box` at n³ cells; returns the box of the cells that may hold the hull
// (empty if none) and whether one of them lies on the box's boundary.
Eigen::AlignedBox3d conservative_box(const std::vector<View>& views, const Eigen::AlignedBox3d& box, int n, bool& touches) {
  const Eigen::Vector3d cell = (box.max() - box.min()) / double(n);
  const double r = 0.5 * cell.norm();
  std::vector<std::uint8_t> keep(std::size_t(n) * n * n, 0);
#pragma omp parallel for schedule(dynamic, 1)
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Eigen::Vector3d c = box.min() + cell.cwiseProduct(Eigen::Vector3d(x + 0.5, y + 0.5, z + 0.5));
        bool ok = true;
        for (const View& v : views)
          if (!v.ballMayBeInside(c, r)) {
            ok = false;
            break;
          }
        keep[std::size_t(x) + std::size_t(n) * (std::size_t(y) + std::size_t(n) * std::size_t(z))] = ok;
      }
  Eigen::AlignedBox3d out;
  touches = false;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x)
        if (keep[std::size_t(x) + std::size_t(n) * (std::size_t(y) + std::size_t(n) * std::size_t(z))]) {
          const Eigen::Vector3d lo = box.min() + cell.cwiseProduct(Eigen::Vector3d(x, y, z));
          out.extend(lo);
          out.extend(lo + cell);
          if (x == 0 || y == 0 || z == 0 || x == n - 1 || y == n - 1 || z == n - 1) touches = true;
        }
  return out;
}

Eigen::AlignedBox3d automatic_box(const std::vector<View>& views, int& doublings, const std::string& who) {
  Eigen::AlignedBox3d cams;
  for (const View& v : views) cams.extend(v.cam->center());
  const double extent = (cams.max() - cams.min()).maxCoeff();
  if (!(extent > 0))
    throw InvalidInput(who + "the camera centres coincide, so they bound no volume: give VisualHullOptions::box (the region to carve)");
  const Eigen::Vector3d c = cams.center();
  Eigen::AlignedBox3d box(c - Eigen::Vector3d::Constant(0.5 * extent), c + Eigen::Vector3d::Constant(0.5 * extent));
  constexpr int kCells = 48;
  doublings = 0;
  for (;;) {
    bool touches = false;
    const Eigen::AlignedBox3d kept = conservative_box(views, box, kCells, touches);
    if (kept.isEmpty())
      throw InvalidInput(who + "the silhouettes' viewing cones do not intersect in the region the cameras surround: check the "
                               "calibration (world units, camera order) and that every camera sees the performer");
    if (touches && doublings < 3) {
      const Eigen::Vector3d h = box.max() - box.center();
      box = Eigen::AlignedBox3d(box.center() - 2 * h, box.center() + 2 * h);
      ++doublings;
      continue;
    }
    // a second conservative pass on the kept region tightens the box
    bool t2 = false;
    const Eigen::AlignedBox3d tight = conservative_box(views, kept, kCells, t2);
    return tight.isEmpty() ? kept : tight;
  }
}

}  // namespace

VisualHull compute_visual_hull(const std::vector<Camera>& cameras, const std::vector<cv::Mat>& silhouettes, const VisualHullOptions& o) {
  const std::string who = "[tbsp::compute_visual_hull] ";
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput(who + why);
  detail::check_silhouettes(cameras, silhouettes, who);
  const std::size_t n = cameras.size();
  std::vector<View> views(n);
  for (std::size_t k = 0; k < n; ++k) {
    View& v = views[k];
    v.cam = &cameras[k];
    v.mask = silhouettes[k] >= 128;
    if (o.margin_px > 0) {
      const cv::Mat se = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * o.margin_px + 1, 2 * o.margin_px + 1));
      cv::dilate(v.mask, v.mask, se);
    }
    cv::Mat background = v.mask == 0;  // distanceTransform: distance to the nearest zero (= foreground) pixel
    cv::distanceTransform(background, v.dist_fg, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  }
  VisualHull h;
  Eigen::AlignedBox3d box = o.box;
  if (box.isEmpty()) box = automatic_box(views, h.box_doublings, who);

  // voxel grid over the box, one voxel of margin on every side so that the surface closes
  const Eigen::Vector3d ext = box.max() - box.min();
  h.voxel = ext.maxCoeff() / double(o.resolution);
  for (int a = 0; a < 3; ++a) h.dims[a] = int(std::ceil(ext[a] / h.voxel)) + 2;
  h.origin = box.min() - 0.5 * h.voxel * Eigen::Vector3d::Ones();
  const int nx = h.dims.x(), ny = h.dims.y(), nz = h.dims.z();
  h.occupied.assign(std::size_t(nx) * ny * nz, 0);
#pragma omp parallel for schedule(dynamic, 1)
  for (int z = 1; z < nz - 1; ++z)
    for (int y = 1; y < ny - 1; ++y)
      for (int x = 1; x < nx - 1; ++x) h.occupied[h.index(x, y, z)] = inside_all(views, h.center(x, y, z));
  if (h.occupiedCount() == 0)
    throw InvalidInput(who + "no voxel centre projects inside every silhouette (voxel " + std::to_string(h.voxel) +
                       "): raise the resolution, or check the calibration and silhouettes");

  // surface samples: one per face between an occupied and a free voxel, by bisection
  auto occ = [&](int x, int y, int z) -> int {
    if (x < 0 || y < 0 || z < 0 || x >= nx || y >= ny || z >= nz) return 0;
    return h.occupied[h.index(x, y, z)];
  };
  static const int kDir[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  std::vector<std::vector<Eigen::Vector3d>> pts(static_cast<std::size_t>(nz)), nrm(static_cast<std::size_t>(nz));
#pragma omp parallel for schedule(dynamic, 1)
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        if (!occ(x, y, z)) continue;
        Eigen::Vector3d g = Eigen::Vector3d::Zero();  // outward: towards decreasing occupancy
        bool grad = false;
        for (int d = 0; d < 6; ++d) {
          const int X = x + kDir[d][0], Y = y + kDir[d][1], Z = z + kDir[d][2];
          if (occ(X, Y, Z)) continue;
          if (!grad) {
            for (int dz = -1; dz <= 1; ++dz)
              for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) g -= double(occ(x + dx, y + dy, z + dz)) * Eigen::Vector3d(dx, dy, dz);
            grad = true;
          }
          Eigen::Vector3d a = h.center(x, y, z), b = h.center(X, Y, Z);
          for (int s = 0; s < 10; ++s) {
            const Eigen::Vector3d m = 0.5 * (a + b);
            (inside_all(views, m) ? a : b) = m;
          }
          const Eigen::Vector3d face(kDir[d][0], kDir[d][1], kDir[d][2]);
          pts[std::size_t(z)].push_back(0.5 * (a + b));
          nrm[std::size_t(z)].push_back(g.norm() > 1e-9 ? Eigen::Vector3d(g.normalized()) : face);
        }
      }
  std::size_t total = 0;
  for (const auto& p : pts) total += p.size();
  h.points.resize(Eigen::Index(total), 3);
  h.normals.resize(Eigen::Index(total), 3);
  Eigen::Index r = 0;
  for (int z = 0; z < nz; ++z)
    for (std::size_t i = 0; i < pts[std::size_t(z)].size(); ++i, ++r) {
      h.points.row(r) = pts[std::size_t(z)][i].transpose();
      h.normals.row(r) = nrm[std::size_t(z)][i].transpose();
    }
  return h;
}

SimilarityIcpOptions default_hull_icp_options() {
  SimilarityIcpOptions o;
  o.symmetric = true;
  o.trim = 0.2;
  o.estimate_scale = true;
  o.max_iterations = 400;
  o.max_points = 20000;
  return o;
}

namespace {

double mean_iou(const TriMesh& mesh, const std::vector<Camera>& cameras, const std::vector<cv::Mat>& silhouettes) {
  RasterOptions ro;
  ro.barycentrics = false;
  const std::vector<RenderBuffers> buf = Rasterizer(ro).renderViews(mesh, cameras);
  double s = 0;
  for (std::size_t k = 0; k < cameras.size(); ++k) s += detail::silhouette_overlap(buf[k].mask, silhouettes[k]).iou;
  return s / double(cameras.size());
}

}  // namespace

HullRegistration register_to_visual_hull(const TriMesh& mesh, const std::vector<Camera>& cameras, const std::vector<cv::Mat>& silhouettes,
                                         const VisualHullOptions& hull_options, const SimilarityIcpOptions& icp) {
  const std::string who = "[tbsp::register_to_visual_hull] ";
  const auto t0 = Clock::now();
  if (mesh.V.rows() < 3 || mesh.F.rows() < 1) throw InvalidInput(who + "the template is empty: give a surface mesh");
  if (!mesh.V.allFinite()) throw InvalidInput(who + "the template has non-finite vertices");
  const VisualHull hull = compute_visual_hull(cameras, silhouettes, hull_options);
  HullRegistration r;
  r.hull_points = int(hull.points.rows());
  r.voxel = hull.voxel;
  r.iou_before = mean_iou(mesh, cameras, silhouettes);
  r.icp = similarity_icp(mesh.V, hull.points, icp, &hull.normals);
  TriMesh moved = mesh;
  moved.V = transform_points(r.icp.transform, mesh.V);
  r.iou_after = mean_iou(moved, cameras, silhouettes);
  r.seconds = seconds_since(t0);
  return r;
}

}  // namespace tbsp
