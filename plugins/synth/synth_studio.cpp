#include "tbsp/plugins/synth_studio.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <random>

#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>
#include <pcl/io/pcd_io.h>

#include "tbsp/io/render_images.h"
#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/multiview/range_scanner.h"
#include "tbsp/multiview/rasterizer.h"

namespace fs = std::filesystem;

namespace tbsp::synth {

namespace {

void append(Humanoid& h, const TriMesh& m, int part) {
  const Eigen::Index n0 = h.mesh.V.rows(), f0 = h.mesh.F.rows();
  h.mesh.V.conservativeResize(n0 + m.V.rows(), 3);
  h.mesh.V.bottomRows(m.V.rows()) = m.V;
  h.mesh.F.conservativeResize(f0 + m.F.rows(), 3);
  h.mesh.F.bottomRows(m.F.rows()) = m.F.array() + static_cast<int>(n0);
  h.part.insert(h.part.end(), static_cast<std::size_t>(m.V.rows()), part);
}

// A tube from `a` to `b` (make_tube runs along +x) with a radius profile r(s), s in [0,1].
TriMesh limb(const Eigen::Vector3d& a, const Eigen::Vector3d& b, int rings, int segments,
             const std::function<double(double)>& radius) {
  const double L = (b - a).norm();
  TriMesh t = make_tube(rings, segments, L, 1.0);
  for (Eigen::Index i = 0; i < t.V.rows(); ++i) {
    const double s = std::clamp(t.V(i, 0) / L, 0.0, 1.0);
    t.V(i, 1) *= radius(s);
    t.V(i, 2) *= radius(s);
  }
  const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitX(), (b - a).normalized());
  for (Eigen::Index i = 0; i < t.V.rows(); ++i) t.V.row(i) = (q * t.V.row(i).transpose() + a).transpose();
  return t;
}

// Hashed lattice value noise in [0,1], trilinear with smoothstep.
double lattice(int x, int y, int z, std::uint32_t seed) {
  std::uint32_t h = static_cast<std::uint32_t>(x) * 73856093u ^ static_cast<std::uint32_t>(y) * 19349663u ^
                    static_cast<std::uint32_t>(z) * 83492791u ^ seed * 2654435761u;
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  h ^= h >> 15;
  return (h & 0xffffff) / double(0xffffff);
}
double value_noise(const Eigen::Vector3d& p, std::uint32_t seed) {
  const Eigen::Vector3d f = p.array().floor();
  const int x = int(f.x()), y = int(f.y()), z = int(f.z());
  Eigen::Vector3d t = p - f;
  t = t.array() * t.array() * (3.0 - 2.0 * t.array());
  double v = 0;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const double w = (dx ? t.x() : 1 - t.x()) * (dy ? t.y() : 1 - t.y()) * (dz ? t.z() : 1 - t.z());
    v += w * lattice(x + dx, y + dy, z + dz, seed);
  }
  return v;
}
// Solid texture: colourful blobs at 3 scales (2.5 cm .. 10 cm features), high contrast.
cv::Vec3b solid_texture(const Eigen::Vector3d& rest) {
  double c[3];
  for (int ch = 0; ch < 3; ++ch) {
    double v = 0.5 * value_noise(rest * 10.0, 11 + ch) + 0.3 * value_noise(rest * 25.0, 31 + ch) + 0.2 * value_noise(rest * 60.0, 71 + ch);
    c[ch] = std::clamp((v - 0.5) * 3.0 + 0.5, 0.0, 1.0);
  }
  return {static_cast<std::uint8_t>(40 + 200 * c[0]), static_cast<std::uint8_t>(40 + 200 * c[1]), static_cast<std::uint8_t>(40 + 200 * c[2])};
}

// Cloth-like folds along the vertex normals (see make_humanoid in the header).
void add_folds(Humanoid& h, double a) {
  const Eigen::MatrixX3d N = vertex_normals(h.mesh.V, h.mesh.F);
  for (Eigen::Index i = 0; i < h.mesh.V.rows(); ++i) {
    const Eigen::Vector3d p = h.mesh.V.row(i);
    const int part = h.part[static_cast<std::size_t>(i)];
    double d = 0;
    if (part == 6) {  // pleats: 12 around, deeper towards the hem
      const double s = std::clamp((0.98 - p.y()) / 0.48, 0.0, 1.0);
      d = a * (0.3 + 0.7 * s) * std::cos(12.0 * std::atan2(p.z(), p.x()));
    } else if (part == 0) {  // horizontal wrinkles, stronger at the front
      d = 0.6 * a * std::sin(2 * M_PI * (p.y() - 0.85) / 0.08) * (0.75 + 0.25 * std::cos(std::atan2(p.x(), p.z())));
    } else if (part == 2 || part == 3) {  // sleeve wrinkles
      d = 0.4 * a * std::sin(2 * M_PI * p.y() / 0.06);
    }
    h.mesh.V.row(i) += d * N.row(i);
  }
}

// The studio's lights (unit directions towards them): a key light from above the front, a fill
// light from the back.
const Eigen::Vector3d kKeyLight = Eigen::Vector3d(0.3, 0.8, 0.6).normalized();
const Eigen::Vector3d kFillLight = Eigen::Vector3d(-0.4, 0.3, -0.8).normalized();

}  // namespace

Humanoid make_humanoid(int detail, double folds) {
  if (detail < 0 || detail > 3) throw InvalidInput("[tbsp::synth::make_humanoid] detail must be 0..3");
  if (!(folds >= 0.0) || folds > 0.05) throw InvalidInput("[tbsp::synth::make_humanoid] folds must be 0..0.05 metres");
  const int k = 1 << detail;  // resolution multiplier
  Humanoid h;
  h.mesh.V.resize(0, 3);
  h.mesh.F.resize(0, 3);
  auto torso_r = [](double s) { return 0.13 + 0.03 * std::sin(M_PI * s); };
  append(h, limb({0, 0.85, 0}, {0, 1.45, 0}, 12 * k, 16 * k, torso_r), 0);
  TriMesh head = make_icosphere(2 + std::min(detail, 2), 0.11);
  head.V.rowwise() += Eigen::RowVector3d(0, 1.58, 0);
  append(h, head, 1);
  auto arm_r = [](double s) { return 0.045 - 0.01 * s; };
  append(h, limb({-0.2, 1.42, 0}, {-0.24, 0.82, 0}, 10 * k, 10 * k, arm_r), 2);
  append(h, limb({0.2, 1.42, 0}, {0.24, 0.82, 0}, 10 * k, 10 * k, arm_r), 3);
  auto leg_r = [](double s) { return 0.07 - 0.025 * s; };
  append(h, limb({-0.09, 0.88, 0}, {-0.1, 0.02, 0}, 14 * k, 10 * k, leg_r), 4);
  append(h, limb({0.09, 0.88, 0}, {0.1, 0.02, 0}, 14 * k, 10 * k, leg_r), 5);
  auto skirt_r = [](double s) { return 0.16 + 0.2 * s * s; };
  append(h, limb({0, 0.98, 0}, {0, 0.5, 0}, 10 * k, 24 * k, skirt_r), 6);
  if (folds > 0) add_folds(h, folds);
  return h;
}

TriMesh animate_humanoid(const Humanoid& h, double t) {
  TriMesh m = h.mesh;
  const double w = 2 * M_PI * 1.0 * t;  // 1 Hz gait
  auto rot_about = [&](Eigen::Index i, const Eigen::Vector3d& pivot, const Eigen::Matrix3d& R) {
    m.V.row(i) = (R * (m.V.row(i).transpose() - pivot) + pivot).transpose();
  };
  const Eigen::Vector3d sl(-0.2, 1.42, 0), sr(0.2, 1.42, 0), hl(-0.09, 0.88, 0), hr(0.09, 0.88, 0), waist(0, 0.98, 0);
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
    const int p = h.part[static_cast<std::size_t>(i)];
    if (p == 2) rot_about(i, sl, Eigen::AngleAxisd(0.52 * std::sin(w), Eigen::Vector3d::UnitX()).toRotationMatrix());
    if (p == 3) rot_about(i, sr, Eigen::AngleAxisd(-0.52 * std::sin(w), Eigen::Vector3d::UnitX()).toRotationMatrix());
    if (p == 4) rot_about(i, hl, Eigen::AngleAxisd(-0.35 * std::sin(w), Eigen::Vector3d::UnitX()).toRotationMatrix());
    if (p == 5) rot_about(i, hr, Eigen::AngleAxisd(0.35 * std::sin(w), Eigen::Vector3d::UnitX()).toRotationMatrix());
    if (p == 6) {  // sway: a bend that grows towards the hem
      const double d = std::clamp((waist.y() - m.V(i, 1)) / 0.48, 0.0, 1.0);
      rot_about(i, waist, Eigen::AngleAxisd(0.15 * d * std::sin(w - 0.8), Eigen::Vector3d::UnitZ()).toRotationMatrix());
    }
  }
  // Whole body: turn slowly and step forward.
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.35 * t, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Vector3d T(0, 0.02 * std::abs(std::sin(w)), 0.15 * t);
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) m.V.row(i) = (R * m.V.row(i).transpose() + T).transpose();
  return m;
}

namespace {

void check_options(const StudioOptions& o, const std::string& who) {
  if (o.cameras < 1 || o.cameras > 64) throw InvalidInput(who + "cameras must be 1..64 (got " + std::to_string(o.cameras) + ")");
  if (o.width < 16 || o.height < 16 || o.width > 8192 || o.height > 8192) throw InvalidInput(who + "image size must be 16..8192 pixels");
  if (o.frames < 1 || o.frames > 100000) throw InvalidInput(who + "frames must be >= 1");
  if (!(o.frame_rate > 0)) throw InvalidInput(who + "frame rate must be positive");
  if (o.image_noise < 0 || o.scan_noise < 0) throw InvalidInput(who + "noise must be >= 0");
  if (o.markers < 0) throw InvalidInput(who + "markers must be >= 0");
}

// The studio's frame range, file patterns and folders; cameras from `eyes` looking at `target`.
void setup_studio(const std::string& dir, const StudioOptions& o, const std::string& name, const std::vector<Eigen::Vector3d>& eyes,
                  const Eigen::Vector3d& target, double hfov, Studio& s) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) throw FileError("'" + dir + "': cannot create the output folder (" + ec.message() + ")");
  s.path = (fs::path(dir) / "studio.yaml").string();
  s.name = name;
  s.frame_rate = o.frame_rate;
  s.first_frame = 0;
  s.last_frame = o.frames - 1;
  s.template_mesh = "template.ply";
  s.ground_truth = "gt/%04d.ply";
  for (std::size_t c = 0; c < eyes.size(); ++c) {
    StudioCamera sc;
    sc.camera = Camera::lookAt("cam" + std::to_string(c), o.width, o.height, hfov, eyes[c], target, {0, 1, 0});
    sc.images = "images/cam" + std::to_string(c) + "/%04d.png";
    sc.silhouettes = "silhouettes/cam" + std::to_string(c) + "/%04d.png";
    s.cameras.push_back(sc);
    fs::create_directories(fs::path(dir) / "images" / sc.camera.name());
    fs::create_directories(fs::path(dir) / "silhouettes" / sc.camera.name());
    if (o.range_scans) fs::create_directories(fs::path(dir) / "scans" / sc.camera.name());
    if (o.depth_images) fs::create_directories(fs::path(dir) / "depth" / sc.camera.name());
  }
  fs::create_directories(fs::path(dir) / "gt");
}

// Renders frame f (mesh m; `rest` carries the solid texture) into every camera: image,
// silhouette [, range scan]. Throws FileError naming what could not be written.
void render_frame(const std::string& dir, const Studio& s, const TriMesh& rest, const TriMesh& m, int f, const StudioOptions& o,
                  const std::string& who) {
  const Rasterizer raster;
  const Eigen::MatrixX3d VN = vertex_normals(m.V, m.F);
  std::vector<std::string> errors(s.cameras.size());
#pragma omp parallel for schedule(dynamic, 1)
  for (int c = 0; c < static_cast<int>(s.cameras.size()); ++c) {
    try {
      const Camera& cam = s.cameras[std::size_t(c)].camera;
      RenderBuffers b;
      raster.render(m, cam, b);
      cv::Mat img(o.height, o.width, CV_8UC3);
      std::mt19937_64 rng(o.seed * 1000003ull + static_cast<std::uint64_t>(f) * 131ull + static_cast<std::uint64_t>(c));
      std::normal_distribution<double> gauss(0.0, 1.0);
      const Eigen::Vector3d C = cam.center();
      for (int y = 0; y < o.height; ++y) {
        auto* row = img.ptr<cv::Vec3b>(y);
        for (int x = 0; x < o.width; ++x) {
          const std::size_t i = static_cast<std::size_t>(y) * o.width + x;
          cv::Vec3b col(70, 75, 80);  // studio backdrop
          const int fi = b.face[i];
          if (fi >= 0) {
            const double b1 = b.bary[2 * i], b2 = b.bary[2 * i + 1], b0 = 1 - b1 - b2;
            const Eigen::Vector3d r = b0 * rest.V.row(m.F(fi, 0)).transpose() + b1 * rest.V.row(m.F(fi, 1)).transpose() +
                                      b2 * rest.V.row(m.F(fi, 2)).transpose();
            const Eigen::Vector3d X = b0 * m.V.row(m.F(fi, 0)).transpose() + b1 * m.V.row(m.F(fi, 1)).transpose() +
                                      b2 * m.V.row(m.F(fi, 2)).transpose();
            // Lambertian under the studio's fixed lights (view-independent radiance, as
            // multi-view stereo assumes), smooth-shaded with interpolated vertex normals.
            Eigen::Vector3d nrm = (b0 * VN.row(m.F(fi, 0)) + b1 * VN.row(m.F(fi, 1)) + b2 * VN.row(m.F(fi, 2))).transpose();
            nrm.normalize();
            if (nrm.dot(C - X) < 0) nrm = -nrm;  // inside of an open part
            const double shade = 0.4 + 0.45 * std::max(0.0, nrm.dot(kKeyLight)) + 0.25 * std::max(0.0, nrm.dot(kFillLight));
            const cv::Vec3b t = solid_texture(r);
            for (int ch = 0; ch < 3; ++ch) col[ch] = static_cast<std::uint8_t>(std::clamp(t[ch] * shade, 0.0, 255.0));
          }
          if (o.image_noise > 0)
            for (int ch = 0; ch < 3; ++ch) col[ch] = static_cast<std::uint8_t>(std::clamp(col[ch] + o.image_noise * gauss(rng), 0.0, 255.0));
          row[x] = col;
        }
      }
      auto save = [&](const std::string& path, const cv::Mat& im) {
        atomic_write_with(path, [&](const std::string& tmp) { return cv::imwrite(tmp + ".png", im) && (fs::rename(tmp + ".png", tmp), true); });
      };
      save(s.imagePath(c, f), img);
      save(s.silhouettePath(c, f), mask_image(b));
      if (o.range_scans || o.depth_images) {
        RangeScanOptions ro;
        ro.noise_sigma = o.scan_noise;
        ro.stride = o.scan_stride;
        ro.seed = o.seed + static_cast<std::uint64_t>(f) * 64 + static_cast<std::uint64_t>(c);
        const auto cloud = range_scan(m, cam, ro);
        if (o.range_scans) {
          const std::string p = (fs::path(dir) / "scans" / cam.name() / (expand_frame_pattern("%04d", f) + ".pcd")).string();
          atomic_write_with(p, [&](const std::string& tmp) { return pcl::io::savePCDFileBinary(tmp, cloud) == 0; });
        }
        if (o.depth_images) {  // the same samples as depth along the optical axis, 0.2 mm units
          cv::Mat d(int(cloud.height), int(cloud.width), CV_16UC1, cv::Scalar(0));
          for (int v = 0; v < d.rows; ++v)
            for (int u = 0; u < d.cols; ++u) {
              const auto& q = cloud.at(u, v);
              if (!std::isfinite(q.z)) continue;
              const double z = (cam.R() * Eigen::Vector3d(q.x, q.y, q.z) + cam.t()).z();
              d.at<std::uint16_t>(v, u) = static_cast<std::uint16_t>(std::clamp(std::lround(z / 0.0002), 1L, 65535L));
            }
          save((fs::path(dir) / "depth" / cam.name() / (expand_frame_pattern("%04d", f) + ".png")).string(), d);
        }
      }
    } catch (const std::exception& e) {
      errors[static_cast<std::size_t>(c)] = e.what();
    }
  }
  for (const auto& e : errors)
    if (!e.empty()) throw FileError(who + e);
}

}  // namespace

StudioResult write_synthetic_studio(const std::string& dir, const StudioOptions& o, const ProgressCallback& progress) {
  const std::string who = "[tbsp synth-studio] ";
  check_options(o, who);
  const Humanoid hum = make_humanoid(o.detail, o.folds);
  StudioResult res;
  res.vertices = static_cast<int>(hum.mesh.V.rows());
  res.faces = static_cast<int>(hum.mesh.F.rows());
  Studio& s = res.studio;
  // Cameras on a ring around the performer, alternating heights, all looking at the hips.
  const double hfov = 2 * std::atan(1.05 / 3.6 * std::max(1.0, double(o.width) / o.height));
  std::vector<Eigen::Vector3d> eyes;
  for (int c = 0; c < o.cameras; ++c) {
    const double a = 2 * M_PI * c / o.cameras + 0.3;
    eyes.emplace_back(3.6 * std::sin(a), (c % 2) ? 2.1 : 1.1, 3.6 * std::cos(a));
  }
  setup_studio(dir, o, "tbsp synthetic studio (procedural humanoid with a skirt)", eyes, {0, 0.9, 0.1 * o.frames / o.frame_rate}, hfov, s);
  if (o.markers > 0) s.markers = "markers.trc";
  write_mesh((fs::path(dir) / "template.ply").string(), hum.mesh);

  // Markers: farthest-point samples of the rest pose.
  std::vector<int> marker_vertices;
  if (o.markers > 0) {
    const Eigen::MatrixX3d& V = hum.mesh.V;
    marker_vertices.push_back(0);
    Eigen::VectorXd d = (V.rowwise() - V.row(0)).rowwise().norm();
    while (static_cast<int>(marker_vertices.size()) < std::min<int>(o.markers, static_cast<int>(V.rows()))) {
      Eigen::Index i;
      d.maxCoeff(&i);
      marker_vertices.push_back(static_cast<int>(i));
      d = d.cwiseMin((V.rowwise() - V.row(i)).rowwise().norm());
    }
  }
  MarkerTrajectories mk;
  mk.frame_rate = o.frame_rate;
  mk.first_frame = 0;
  mk.units = "m";
  for (int v : marker_vertices) mk.names.push_back("V" + std::to_string(v));
  mk.data.resize(o.frames, 3 * static_cast<Eigen::Index>(marker_vertices.size()));

  for (int f = 0; f < o.frames; ++f) {
    report_progress(progress, double(f) / o.frames, "rendering");
    const TriMesh m = animate_humanoid(hum, f / o.frame_rate);
    for (std::size_t k = 0; k < marker_vertices.size(); ++k) mk.data.block<1, 3>(f, 3 * static_cast<Eigen::Index>(k)) = m.V.row(marker_vertices[k]);
    write_mesh(s.groundTruthPath(f), m);
    render_frame(dir, s, hum.mesh, m, f, o, who);
    res.images_written += 2 * o.cameras;
  }
  if (o.markers > 0) write_trc((fs::path(dir) / "markers.trc").string(), mk);
  write_studio(s.path, s);  // last: a complete dataset
  report_progress(progress, 1.0, "done");
  return res;
}

StudioResult write_sequence_studio(const std::string& dir, const TriMesh& rest, const std::function<TriMesh(int)>& frame,
                                   const StudioOptions& o, const ProgressCallback& progress) {
  const std::string who = "[tbsp::synth::write_sequence_studio] ";
  check_options(o, who);
  if (rest.V.rows() < 4 || rest.F.rows() < 4) throw InvalidInput(who + "the rest mesh is empty");
  // The sequence's extent (y up): cameras on a ring of radius 2 x its height around its centre.
  Eigen::RowVector3d lo = rest.V.colwise().minCoeff(), hi = rest.V.colwise().maxCoeff();
  for (int f = 0; f < o.frames; ++f) {
    const TriMesh m = frame(f);
    if (m.V.rows() != rest.V.rows() || m.F.rows() != rest.F.rows())
      throw InvalidInput(who + "frame " + std::to_string(f) + " has " + std::to_string(m.V.rows()) + " vertices / " + std::to_string(m.F.rows()) +
                         " faces; the rest mesh has " + std::to_string(rest.V.rows()) + " / " + std::to_string(rest.F.rows()) + " (constant connectivity needed)");
    lo = lo.cwiseMin(m.V.colwise().minCoeff());
    hi = hi.cwiseMax(m.V.colwise().maxCoeff());
  }
  const Eigen::Vector3d c = (0.5 * (lo + hi)).transpose();
  const double H = std::max(hi(1) - lo(1), 1e-9), R = 2.0 * H;
  const double reach = 0.55 * std::max(H, std::max(hi(0) - lo(0), hi(2) - lo(2)));
  const double hfov = 2 * std::atan(reach / R * std::max(1.0, double(o.width) / o.height));
  std::vector<Eigen::Vector3d> eyes;
  for (int k = 0; k < o.cameras; ++k) {
    const double a = 2 * M_PI * k / o.cameras + 0.3;
    eyes.emplace_back(c.x() + R * std::sin(a), c.y() + ((k % 2) ? 0.65 : 0.1) * H, c.z() + R * std::cos(a));
  }
  StudioResult res;
  res.vertices = static_cast<int>(rest.V.rows());
  res.faces = static_cast<int>(rest.F.rows());
  Studio& s = res.studio;
  setup_studio(dir, o, "tbsp studio rendered around a mesh sequence", eyes, c, hfov, s);
  write_mesh((fs::path(dir) / "template.ply").string(), rest);
  for (int f = 0; f < o.frames; ++f) {
    report_progress(progress, double(f) / o.frames, "rendering");
    const TriMesh m = frame(f);
    write_mesh(s.groundTruthPath(f), m);
    render_frame(dir, s, rest, m, f, o, who);
    res.images_written += 2 * o.cameras;
  }
  write_studio(s.path, s);
  report_progress(progress, 1.0, "done");
  return res;
}

}  // namespace tbsp::synth
