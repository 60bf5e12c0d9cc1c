#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

#include "tbsp/io/render_images.h"
#include "tbsp/core/error.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/multiview/range_scanner.h"
#include "tbsp/multiview/rasterizer.h"

using namespace tbsp;

namespace {
// Exact hit depth (camera z) of the ray through pixel (x, y) with a sphere (centre S, radius r);
// negative when the ray misses.
double sphere_depth(const Camera& cam, int x, int y, const Eigen::Vector3d& S, double r) {
  const Ray ray = cam.ray({double(x), double(y)});
  const Eigen::Vector3d oc = ray.origin - S;
  const double b = oc.dot(ray.direction), c = oc.squaredNorm() - r * r, disc = b * b - c;
  if (disc < 0) return -1;
  const double s = -b - std::sqrt(disc);
  return cam.depth(ray.origin + s * ray.direction);
}
}  // namespace

TEST(Rasterizer, SphereSilhouetteAndDepthMatchTheExactProjection) {
  const double r = 1.0;
  const Eigen::Vector3d S(0.3, -0.2, 0.1);
  TriMesh sphere = make_icosphere(6, r);
  sphere.V.rowwise() += S.transpose();
  // An off-centre view (the silhouette is an ellipse) and a closer, wide one.
  const std::vector<Camera> cams = {Camera::lookAt("a", 1004, 1004, 0.7, {3.5, 1.0, 2.0}, {1.0, 0.3, 0.0}, {0, 1, 0}),
                                    Camera::lookAt("b", 640, 480, 1.4, {-0.5, 2.5, -2.5}, S, {0, 0, 1})};
  const auto bufs = Rasterizer().renderViews(sphere, cams);
  for (std::size_t v = 0; v < cams.size(); ++v) {
    const Camera& cam = cams[v];
    const RenderBuffers& b = bufs[v];
    long inter = 0, uni = 0;
    std::vector<double> derr;
    for (int y = 0; y < cam.height(); ++y)
      for (int x = 0; x < cam.width(); ++x) {
        const double zd = sphere_depth(cam, x, y, S, r);
        const bool exact = zd > 0, ours = b.covered(x, y);
        inter += exact && ours;
        uni += exact || ours;
        if (exact && ours) derr.push_back(std::abs(b.depth[y * b.width + x] - zd));
      }
    const double iou = double(inter) / double(uni);
    EXPECT_GE(iou, 0.995) << cam.name();
    std::sort(derr.begin(), derr.end());
    EXPECT_LT(derr[derr.size() / 2], 2e-4 * r) << cam.name();  // inscribed polytope: chord sag ~1e-4 r
    EXPECT_LT(derr[derr.size() * 99 / 100], 5e-3 * r) << cam.name();
    EXPECT_EQ(b.skipped_near, 0);
    std::printf("  view %s: IoU %.5f, %ld px, median depth error %.2e r\n", cam.name().c_str(), iou, inter,
                derr[derr.size() / 2] / r);
  }
}

TEST(Rasterizer, BarycentricsArePerspectiveCorrect) {
  const TriMesh sphere = make_icosphere(4, 1.0);
  const Camera cam = Camera::lookAt("c", 320, 240, 1.2, {0, 0, 3}, {0, 0, 0}, {0, 1, 0});
  RenderBuffers b;
  Rasterizer().render(sphere, cam, b);
  double worst = 0;
  int n = 0;
  for (int y = 0; y < b.height; ++y)
    for (int x = 0; x < b.width; ++x) {
      const std::size_t i = std::size_t(y) * b.width + x;
      const int f = b.face[i];
      if (f < 0) continue;
      const double b1 = b.bary[2 * i], b2 = b.bary[2 * i + 1], b0 = 1 - b1 - b2;
      EXPECT_GE(std::min({b0, b1, b2}), -1e-5);
      const Eigen::Vector3d X = b0 * sphere.V.row(sphere.F(f, 0)) + b1 * sphere.V.row(sphere.F(f, 1)) +
                                b2 * sphere.V.row(sphere.F(f, 2));
      const Eigen::Vector2d p = cam.project(X);
      worst = std::max(worst, (p - Eigen::Vector2d(x, y)).norm());
      EXPECT_NEAR(cam.depth(X), b.depth[i], 1e-5);
      ++n;
    }
  EXPECT_GT(n, 5000);
  EXPECT_LT(worst, 2e-3);  // float barycentrics
}

TEST(Rasterizer, PixelBarycentricsEqualTheBarycentricBuffer) {
  // a camera with lens distortion and a tilted view: the helper must project as the render does
  const Camera look = Camera::lookAt("c", 320, 240, 1.2, {0.4, 0.3, 3}, {0, 0, 0}, {0, 1, 0});
  Distortion dist;
  dist.k1 = -0.12;
  dist.k2 = 0.03;
  dist.p1 = 0.001;
  dist.p2 = -0.002;
  const Camera cam("c", 320, 240, look.K(), look.R(), look.t(), dist);
  const TriMesh sphere = make_icosphere(3, 1.0);
  RenderBuffers b;
  Rasterizer().render(sphere, cam, b);
  int n = 0;
  double worst = 0;
  for (int y = 0; y < b.height; ++y)
    for (int x = 0; x < b.width; ++x) {
      const std::size_t i = std::size_t(y) * b.width + x;
      if (b.face[i] < 0) continue;
      const Eigen::Vector3d q = pixel_barycentrics(sphere, cam, b.face[i], x, y);
      const double b1 = b.bary[2 * i], b2 = b.bary[2 * i + 1];
      worst = std::max({worst, std::abs(q(1) - b1), std::abs(q(2) - b2), std::abs(q(0) - (1.0 - b1 - b2))});
      ++n;
    }
  EXPECT_GT(n, 5000);
  EXPECT_LE(worst, 1e-6);  // the same formula; at most the float rounding of b1, b2 apart
  EXPECT_THROW(pixel_barycentrics(sphere, cam, -1, 10, 10), InvalidInput);
  EXPECT_THROW(pixel_barycentrics(sphere, cam, int(sphere.F.rows()), 10, 10), InvalidInput);
  const Camera behind = Camera::lookAt("b", 320, 240, 1.2, {0, 0, 3}, {0, 0, 6}, {0, 1, 0});  // looks away
  EXPECT_THROW(pixel_barycentrics(sphere, behind, 0, 10, 10), InvalidInput);
}

// point_barycentrics: the point of the visible triangle's plane under a sub-pixel position projects
// back onto that position (a pinhole camera: the projected triangle is exactly a triangle), and at
// a pixel centre it agrees with pixel_barycentrics.
TEST(Rasterizer, PointBarycentricsLiftASubPixelPositionExactly) {
  const Camera cam = Camera::lookAt("c", 320, 240, 1.2, {0.4, 0.3, 3}, {0, 0, 0}, {0, 1, 0});
  const TriMesh sphere = make_icosphere(3, 1.0);
  RenderBuffers b;
  Rasterizer().render(sphere, cam, b);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> frac(-0.5, 0.5);
  int n = 0;
  double worst_px = 0, worst_centre = 0;
  for (int y = 0; y < b.height; y += 3)
    for (int x = 0; x < b.width; x += 3) {
      const std::int32_t f = b.face[std::size_t(y) * b.width + x];
      if (f < 0) continue;
      const Eigen::Vector2d p(x + frac(rng), y + frac(rng));
      const Eigen::Vector3d q = point_barycentrics(sphere, cam, f, p);
      Eigen::Vector3d X = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) X += q(k) * sphere.V.row(sphere.F(f, k)).transpose();
      worst_px = std::max(worst_px, (cam.project(X) - p).norm());
      worst_centre = std::max(worst_centre, (point_barycentrics(sphere, cam, f, Eigen::Vector2d(x, y)) -
                                             pixel_barycentrics(sphere, cam, f, x, y)).cwiseAbs().maxCoeff());
      ++n;
    }
  EXPECT_GT(n, 500);
  EXPECT_LT(worst_px, 1e-6);
  EXPECT_LE(worst_centre, 1e-6);  // pixel_barycentrics rounds b1, b2 to float as the buffer does
  EXPECT_THROW(point_barycentrics(sphere, cam, -1, Eigen::Vector2d(10, 10)), InvalidInput);
}

TEST(Rasterizer, SharedEdgesLeaveNoGapsAndBackfacesCanBeCulled) {
  // A plane filling the whole view, finely triangulated with jitter: every pixel covered.
  TriMesh grid = make_grid(40, 30, 4.0, 3.0, 0.15, 7);
  grid.V.rowwise() -= Eigen::RowVector3d(2.0, 1.5, 0.0);
  const Camera cam = Camera::lookAt("g", 200, 150, 1.0, {0, 0, 1.2}, {0, 0, 0}, {0, 1, 0});
  RenderBuffers b;
  Rasterizer().render(grid, cam, b);
  EXPECT_EQ(std::count(b.mask.begin(), b.mask.end(), 255), 200 * 150);
  // The grid faces +z, towards the camera: culling keeps it; from below it disappears.
  RasterOptions cull;
  cull.cull_backfaces = true;
  Rasterizer(cull).render(grid, cam, b);
  EXPECT_EQ(std::count(b.mask.begin(), b.mask.end(), 255), 200 * 150);
  const Camera below = Camera::lookAt("u", 200, 150, 1.0, {0, 0, -1.2}, {0, 0, 0}, {0, 1, 0});
  Rasterizer(cull).render(grid, below, b);
  EXPECT_EQ(std::count(b.mask.begin(), b.mask.end(), 255), 0);
}

TEST(Rasterizer, RimVerticesOfASphereLieOnItsContour) {
  const double r = 1.0;
  const TriMesh sphere = make_icosphere(5, r);
  const Camera cam = Camera::lookAt("c", 800, 600, 0.9, {0.5, 0.8, 3.0}, {0.2, 0, 0}, {0, 1, 0});
  RenderBuffers b;
  Rasterizer().render(sphere, cam, b);
  const std::vector<int> rim = rim_vertices(sphere, cam, b, 1.0);
  ASSERT_GT(rim.size(), 100u);
  const Eigen::Vector3d C = cam.center();
  // Exact contour: the circle of tangency, where (v - C) is perpendicular to the normal v / r.
  double worst_angle = 0, worst_px = 0;
  for (int v : rim) {
    const Eigen::Vector3d X = sphere.V.row(v).transpose();
    const double cosang = X.normalized().dot((X - C).normalized());
    worst_angle = std::max(worst_angle, std::abs(cosang));
    // Distance in pixels to the exact silhouette boundary: walk along the image direction
    // from the vertex until the ray misses the sphere.
    const Eigen::Vector2d p = cam.project(X), dir = (p - cam.project(Eigen::Vector3d::Zero())).normalized();
    double lo = -5, hi = 5;  // hit at lo, miss at hi
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (lo + hi);
      const Ray ray = cam.ray(p + mid * dir);
      const Eigen::Vector3d oc = ray.origin;
      const double bb = oc.dot(ray.direction), disc = bb * bb - (oc.squaredNorm() - r * r);
      (disc >= 0 ? lo : hi) = mid;
    }
    worst_px = std::max(worst_px, std::abs(lo));
  }
  EXPECT_LT(worst_angle, 0.12);  // within ~7 degrees of tangency (vertex spacing on a level-5 sphere)
  EXPECT_LT(worst_px, 1.6);
  std::printf("  %zu rim vertices, max |cos(view, normal)| %.3f, max distance to the exact contour %.2f px\n",
              rim.size(), worst_angle, worst_px);
  // Far-side vertices are never rim vertices.
  for (int v : rim) EXPECT_LT(std::abs(sphere.V.row(v).dot((sphere.V.row(v).transpose() - C).normalized())), 0.2);
}

TEST(RangeScanner, PointsLieOnTheVisibleSideWithTheRequestedNoise) {
  const TriMesh sphere = make_icosphere(5, 1.0);
  const Camera cam = Camera::lookAt("c", 320, 240, 1.0, {0, 0, 3}, {0, 0, 0}, {0, 1, 0});
  RangeScanOptions o;
  o.noise_sigma = 0.01;
  o.stride = 2;
  o.seed = 9;
  const auto cloud = range_scan(sphere, cam, o);
  EXPECT_EQ(cloud.width, 160u);
  EXPECT_EQ(cloud.height, 120u);
  EXPECT_FALSE(cloud.is_dense);
  RangeScanOptions clean_opt = o;
  clean_opt.noise_sigma = 0;
  const auto clean = range_scan(sphere, cam, clean_opt);
  double s2 = 0;
  int n = 0;
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    const auto& p = cloud.points[i];
    ASSERT_EQ(std::isfinite(p.x), std::isfinite(clean.points[i].x));
    if (!std::isfinite(p.x)) continue;
    const Eigen::Vector3d X(p.x, p.y, p.z), N(p.normal_x, p.normal_y, p.normal_z);
    EXPECT_GT(N.dot(cam.center() - X), 0);  // normals face the scanner
    EXPECT_GT(X.z(), -0.2);                   // only the visible hemisphere (+ grazing cut)
    EXPECT_NEAR(clean.points[i].getVector3fMap().norm(), 1.0, 2e-3);  // on the (inscribed) sphere
    s2 += (p.getVector3fMap() - clean.points[i].getVector3fMap()).squaredNorm();
    ++n;
  }
  ASSERT_GT(n, 3000);
  const double rms = std::sqrt(s2 / n);
  EXPECT_NEAR(rms, 0.01, 0.0005);  // the requested noise, along the rays
  // Same seed, same cloud; another seed differs.
  const auto again = range_scan(sphere, cam, o);
  EXPECT_EQ(std::memcmp(again.points.data(), cloud.points.data(), cloud.points.size() * sizeof(pcl::PointNormal)), 0);
  EXPECT_THROW(range_scan(sphere, cam, RangeScanOptions{0.0, 0}), InvalidInput);
  EXPECT_THROW(range_scan(TriMesh{}, cam), InvalidInput);
}

TEST(Rasterizer, TexturedAndVertexColouredShading) {
  // A unit square in z = 0 with uv = (x, y) and a 4x4 checkerboard texture, seen head-on:
  // every pixel shows the texel under its back-projected point.
  TriMesh sq = make_grid(8, 8, 1.0, 1.0);
  Eigen::MatrixX2d uv = sq.V.leftCols<2>();
  cv::Mat tex(64, 64, CV_8UC3);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) tex.at<cv::Vec3b>(y, x) = ((x / 16 + y / 16) % 2) ? cv::Vec3b(255, 255, 255) : cv::Vec3b(0, 0, 200);
  const Camera cam = Camera::lookAt("t", 200, 200, 0.6, {0.5, 0.5, 2.0}, {0.5, 0.5, 0}, {0, 1, 0});
  RenderBuffers b;
  Rasterizer().render(sq, cam, b);
  const cv::Mat img = shade_texture(sq, uv, tex, b, {1, 2, 3});
  int checked = 0, wrong = 0;
  for (int y = 0; y < 200; ++y)
    for (int x = 0; x < 200; ++x) {
      if (!b.covered(x, y)) {
        EXPECT_EQ(img.at<cv::Vec3b>(y, x), cv::Vec3b(1, 2, 3));
        continue;
      }
      const Eigen::Vector3d X = cam.backProject({double(x), double(y)}, b.depth[y * 200 + x]);
      const double fu = X.x() * 4, fv = (1 - X.y()) * 4;  // checker cell coordinates (v up)
      if (std::abs(fu - std::round(fu)) < 0.05 || std::abs(fv - std::round(fv)) < 0.05) continue;  // cell borders blur
      const bool white = (int(std::floor(fu)) + int(std::floor(fv))) % 2;
      wrong += img.at<cv::Vec3b>(y, x) != (white ? cv::Vec3b(255, 255, 255) : cv::Vec3b(0, 0, 200));
      ++checked;
    }
  EXPECT_GT(checked, 5000);
  EXPECT_EQ(wrong, 0);
  // Vertex colours: red varies linearly with x, so the image does too.
  sq.C.resize(sq.V.rows(), 3);
  for (Eigen::Index i = 0; i < sq.V.rows(); ++i) sq.C.row(i) << sq.V(i, 0), 0, 1;
  const cv::Mat vc = shade_vertex_colors(sq, b);
  for (int x = 60; x < 140; x += 20) {
    const Eigen::Vector3d X = cam.backProject({double(x), 100.0}, b.depth[100 * 200 + x]);
    EXPECT_NEAR(vc.at<cv::Vec3b>(100, x)[2], 255 * X.x(), 1.0);
    EXPECT_EQ(vc.at<cv::Vec3b>(100, x)[0], 255);
  }
  EXPECT_THROW(shade_texture(sq, Eigen::MatrixX2d(3, 2), tex, b), InvalidInput);
  RasterOptions nob;
  nob.barycentrics = false;
  Rasterizer(nob).render(sq, cam, b);
  EXPECT_THROW(shade_vertex_colors(sq, b), InvalidInput);
}

// Re-used buffers are reset only inside the previous render's covered box: every re-render
// (a sphere moving across the view, shrinking, leaving it, with and without barycentrics)
// must give exactly the buffers a fresh render gives, and the box must be the covered pixels'.
TEST(Rasterizer, ReusedBuffersEqualFreshOnesAndTheBoxBoundsTheCover) {
  const Camera cam = Camera::lookAt("c", 160, 120, 1.0, {0, 0, 4}, {0, 0, 0}, {0, 1, 0});
  std::vector<TriMesh> meshes;
  for (int i = 0; i < 6; ++i) {
    TriMesh m = make_icosphere(3, 1.0 - 0.12 * i);
    m.V.rowwise() += Eigen::RowVector3d(-1.6 + 0.7 * i, 0.5 - 0.25 * i, 0.0);
    meshes.push_back(m);
  }
  TriMesh away = meshes[0];
  away.V.rowwise() += Eigen::RowVector3d(50, 0, 0);  // outside the view: nothing covered
  meshes.insert(meshes.begin() + 3, away);
  RenderBuffers reused;
  for (std::size_t i = 0; i < meshes.size(); ++i) {
    RasterOptions o;
    o.barycentrics = i % 3 != 1;
    const Rasterizer r(o);
    RenderBuffers fresh;
    r.render(meshes[i], cam, fresh);
    r.render(meshes[i], cam, reused);
    EXPECT_EQ(reused.depth, fresh.depth) << "render " << i;
    EXPECT_EQ(reused.face, fresh.face) << "render " << i;
    EXPECT_EQ(reused.mask, fresh.mask) << "render " << i;
    EXPECT_EQ(reused.bary, fresh.bary) << "render " << i;
    int x0 = 160, x1 = -1, y0 = 120, y1 = -1;
    for (int y = 0; y < 120; ++y)
      for (int x = 0; x < 160; ++x)
        if (fresh.covered(x, y)) x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
    if (x1 < 0) {
      EXPECT_LT(reused.box_x1, reused.box_x0) << "render " << i << ": nothing covered, the box must be empty";
    } else {
      EXPECT_EQ(reused.box_x0, x0);
      EXPECT_EQ(reused.box_x1, x1);
      EXPECT_EQ(reused.box_y0, y0);
      EXPECT_EQ(reused.box_y1, y1);
    }
  }
  // Written into by the caller: markAllDirty() makes the next render reset everything.
  std::fill(reused.mask.begin(), reused.mask.end(), std::uint8_t(7));
  reused.markAllDirty();
  RenderBuffers fresh;
  Rasterizer().render(meshes[1], cam, fresh);
  Rasterizer().render(meshes[1], cam, reused);
  EXPECT_EQ(reused.mask, fresh.mask);
}
