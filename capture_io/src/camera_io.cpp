#include "tbsp/io/camera_io.h"

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <map>
#include <sstream>

#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "text_buffer.h"

namespace fs = std::filesystem;

namespace tbsp {

namespace {

// Runs `make` and re-throws camera validation errors as FileError at the current line.
template <typename F>
Camera checked_camera(detail::TextBuffer& tb, int line, F make) {
  try {
    return make();
  } catch (const FileError&) {
    throw;
  } catch (const InvalidInput& e) {
    throw FileError(tb.path() + ":" + std::to_string(line) + ": " + e.what());
  }
}

std::string fmt(double v) {
  std::ostringstream os;
  os << std::setprecision(17) << v;
  return os.str();
}

}  // namespace

std::vector<Camera> read_middlebury_par(const std::string& path, int width, int height) {
  auto tb = detail::TextBuffer::load(path);
  const long long n = tb.readInt("the number of cameras on the first line");
  if (n <= 0 || n > 100000)
    tb.fail("camera count " + std::to_string(n) + " is not plausible (expected 1..100000); is this a Middlebury *_par.txt file?");
  std::vector<Camera> cams;
  cams.reserve(static_cast<std::size_t>(n));
  for (long long i = 0; i < n; ++i) {
    std::string_view name_tok;
    if (!tb.token(name_tok))
      tb.fail("file ends after " + std::to_string(i) + " of " + std::to_string(n) + " cameras (truncated?)");
    const std::string name(name_tok);
    const int line = tb.line();
    double v[21];
    for (int k = 0; k < 21; ++k) {
      const char* what = k < 9 ? "K entry" : (k < 18 ? "R entry" : "t entry");
      v[k] = tb.readDouble(std::string(what) + " of camera '" + name + "' (21 numbers per line: K, R, t)");
    }
    int w = width, h = height;
    if (w <= 0 || h <= 0) {
      const fs::path img = fs::path(path).parent_path() / name;
      std::error_code iec;
      cv::Mat im;
      if (fs::exists(img, iec)) im = cv::imread(img.string(), cv::IMREAD_UNCHANGED);
      if (im.empty())
        throw FileError(path + ":" + std::to_string(line) + ": the image '" + img.string() +
                        "' is needed for the image size and cannot be read; pass the size explicitly (width, height)");
      w = im.cols;
      h = im.rows;
      width = w;  // same size for all views
      height = h;
    }
    Eigen::Matrix3d K, R;
    K << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
    R << v[9], v[10], v[11], v[12], v[13], v[14], v[15], v[16], v[17];
    const Eigen::Vector3d t(v[18], v[19], v[20]);
    cams.push_back(checked_camera(tb, line, [&] {
      // Middlebury R are orthonormal to ~1e-9 only; re-orthonormalise tiny round-off.
      Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
      Eigen::Matrix3d Rn = svd.matrixU() * svd.matrixV().transpose();
      if ((Rn - R).norm() > 1e-4) Rn = R;  // not a rotation at all: let Camera report it
      return Camera(name, w, h, K, Rn, t);
    }));
  }
  std::string_view extra;
  if (tb.token(extra)) tb.fail("unexpected '" + std::string(extra) + "' after the " + std::to_string(n) + " cameras (wrong count on the first line?)");
  return cams;
}

std::vector<Camera> read_dome_calibration(const std::string& path, int width, int height) {
  if (width <= 0 || height <= 0)
    throw InvalidInput("[tbsp::read_dome_calibration] " + path + ": the image size " + std::to_string(width) + "x" + std::to_string(height) +
                       " is not positive (the file does not store it: 1024x768 for the WD2 / lkB sets)");
  auto tb = detail::TextBuffer::load(path);
  std::vector<Camera> cams;
  std::vector<long long> seen;
  for (;;) {
    tb.skipSpace();
    if (tb.atEnd()) break;
    const long long idx = tb.readInt("the camera index opening a block (index, K, k1 k2, [R|t])");
    const int line = tb.line();
    if (idx < 0 || idx > 100000) tb.fail("camera index " + std::to_string(idx) + " is not plausible (expected 0..100000)");
    for (long long s : seen)
      if (s == idx) tb.fail("camera index " + std::to_string(idx) + " appears twice");
    seen.push_back(idx);
    const std::string name = "cam" + std::to_string(idx);
    double v[23];
    for (int k = 0; k < 23; ++k) {
      const char* what = k < 9 ? "K entry" : (k < 11 ? "distortion coefficient" : (k % 4 == 2 ? "t entry" : "R entry"));
      v[k] = tb.readDouble(std::string(what) + " of camera " + std::to_string(idx) + " (a block: index, K 3x3, k1 k2, [R|t] 3x4)");
    }
    Eigen::Matrix3d K, R;
    K << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
    R << v[11], v[12], v[13], v[15], v[16], v[17], v[19], v[20], v[21];
    const Eigen::Vector3d t(v[14], v[18], v[22]);
    Distortion d;
    d.k1 = v[9];
    d.k2 = v[10];
    cams.push_back(checked_camera(tb, line, [&] {
      // printed with 6 decimals: re-orthonormalise that round-off (not a rotation at all: let Camera report it)
      Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
      Eigen::Matrix3d Rn = svd.matrixU() * svd.matrixV().transpose();
      if ((Rn - R).norm() > 1e-4) Rn = R;
      return Camera(name, width, height, K, Rn, t, d);
    }));
  }
  if (cams.empty()) throw FileError(path + ": no camera (expected blocks of: index, K 3x3, k1 k2, [R|t] 3x4)");
  return cams;
}

void write_middlebury_par(const std::string& path, const std::vector<Camera>& cams) {
  std::ostringstream os;
  os << cams.size() << "\n";
  for (const Camera& c : cams) {
    if (!c.distortion().isZero())
      throw InvalidInput("[tbsp::write_middlebury_par] camera '" + c.name() + "' has lens distortion, which the Middlebury format cannot store; use studio.yaml or COLMAP");
    os << (c.name().empty() ? "view" : c.name());
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) os << ' ' << fmt(c.K()(r, k));
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) os << ' ' << fmt(c.R()(r, k));
    for (int k = 0; k < 3; ++k) os << ' ' << fmt(c.t()(k));
    os << "\n";
  }
  write_text_file_atomic(path, os.str());
}

namespace {
struct ColmapIntrinsics {
  int width = 0, height = 0;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Distortion dist;
};

bool data_line(std::string_view line) {
  for (char c : line) {
    if (c == '#') return false;
    if (!std::isspace(static_cast<unsigned char>(c))) return true;
  }
  return false;
}

std::vector<std::string> split(std::string_view line) {
  std::vector<std::string> out;
  std::istringstream is{std::string(line)};
  std::string s;
  while (is >> s) out.push_back(s);
  return out;
}
}  // namespace

std::vector<Camera> read_colmap_text(const std::string& dir) {
  const std::string cpath = (fs::path(dir) / "cameras.txt").string();
  const std::string ipath = (fs::path(dir) / "images.txt").string();
  auto ct = detail::TextBuffer::load(cpath);
  std::map<long long, ColmapIntrinsics> intr;
  std::string_view line;
  while (ct.nextLine(line)) {
    if (!data_line(line)) continue;
    const int ln = ct.line() - 1;
    auto tok = split(line);
    auto bad = [&](const std::string& m) { throw FileError(cpath + ":" + std::to_string(ln) + ": " + m); };
    if (tok.size() < 4) bad("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    long long id, w, h;
    if (!detail::parse_int(tok[0], id)) bad("camera id '" + tok[0] + "' is not an integer");
    if (!detail::parse_int(tok[2], w) || !detail::parse_int(tok[3], h) || w <= 0 || h <= 0 || w > 1000000 || h > 1000000)
      bad("image size '" + tok[2] + " " + tok[3] + "' is not two positive integers");
    std::vector<double> p;
    for (std::size_t k = 4; k < tok.size(); ++k) {
      double v;
      if (!detail::parse_double(tok[k], v) || !std::isfinite(v)) bad("parameter '" + tok[k] + "' is not a finite number");
      p.push_back(v);
    }
    const std::string& model = tok[1];
    const std::map<std::string, std::size_t> nparams = {
        {"SIMPLE_PINHOLE", 3}, {"PINHOLE", 4}, {"SIMPLE_RADIAL", 4}, {"RADIAL", 5}, {"OPENCV", 8}};
    auto it = nparams.find(model);
    if (it == nparams.end())
      bad("camera model '" + model + "' is not supported (supported: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV); undistort the images with COLMAP's image_undistorter first");
    if (p.size() != it->second)
      bad("model " + model + " takes " + std::to_string(it->second) + " parameters, found " + std::to_string(p.size()));
    ColmapIntrinsics c;
    c.width = int(w);
    c.height = int(h);
    double fx, fy, cx, cy;
    if (model == "SIMPLE_PINHOLE" || model == "SIMPLE_RADIAL" || model == "RADIAL") { fx = fy = p[0]; cx = p[1]; cy = p[2]; }
    else { fx = p[0]; fy = p[1]; cx = p[2]; cy = p[3]; }
    if (model == "SIMPLE_RADIAL") c.dist.k1 = p[3];
    if (model == "RADIAL") { c.dist.k1 = p[3]; c.dist.k2 = p[4]; }
    if (model == "OPENCV") { c.dist.k1 = p[4]; c.dist.k2 = p[5]; c.dist.p1 = p[6]; c.dist.p2 = p[7]; }
    c.K << fx, 0, cx - 0.5, 0, fy, cy - 0.5, 0, 0, 1;
    if (intr.count(id)) bad("camera id " + std::to_string(id) + " is defined twice");
    intr[id] = c;
  }
  if (intr.empty()) throw FileError(cpath + ": no cameras defined");

  auto it_ = detail::TextBuffer::load(ipath);
  std::vector<Camera> cams;
  bool expect_points = false;
  while (it_.nextLine(line)) {
    if (expect_points) {  // the POINTS2D line (may be empty) follows each image line
      expect_points = false;
      if (!data_line(line) || line.find('#') == std::string_view::npos) continue;
    }
    if (!data_line(line)) continue;
    const int ln = it_.line() - 1;
    auto tok = split(line);
    auto bad = [&](const std::string& m) { throw FileError(ipath + ":" + std::to_string(ln) + ": " + m); };
    if (tok.size() != 10) bad("expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (10 fields), found " + std::to_string(tok.size()));
    double q[7];
    for (int k = 0; k < 7; ++k)
      if (!detail::parse_double(tok[1 + k], q[k]) || !std::isfinite(q[k])) bad("'" + tok[1 + k] + "' is not a finite number");
    long long cid;
    if (!detail::parse_int(tok[8], cid)) bad("camera id '" + tok[8] + "' is not an integer");
    auto ci = intr.find(cid);
    if (ci == intr.end()) bad("camera id " + std::to_string(cid) + " is not defined in cameras.txt");
    Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
    if (std::abs(quat.norm() - 1.0) > 1e-3) bad("quaternion norm " + std::to_string(quat.norm()) + " is not 1");
    quat.normalize();
    const ColmapIntrinsics& c = ci->second;
    try {
      cams.emplace_back(tok[9], c.width, c.height, c.K, quat.toRotationMatrix(), Eigen::Vector3d(q[4], q[5], q[6]), c.dist);
    } catch (const InvalidInput& e) {
      bad(e.what());
    }
    expect_points = true;
  }
  if (cams.empty()) throw FileError(ipath + ": no images defined");
  return cams;
}

void write_colmap_text(const std::string& dir, const std::vector<Camera>& cams) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  std::ostringstream cs, is;
  cs << "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n# written by tbsp\n";
  is << "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n";
  for (std::size_t i = 0; i < cams.size(); ++i) {
    const Camera& c = cams[i];
    if (std::abs(c.K()(0, 1)) > 1e-12)
      throw InvalidInput("[tbsp::write_colmap_text] camera '" + c.name() + "' has skew, which COLMAP cannot store");
    if (c.distortion().k3 != 0)
      throw InvalidInput("[tbsp::write_colmap_text] camera '" + c.name() + "' has k3 != 0, which COLMAP's OPENCV model cannot store");
    const auto& K = c.K();
    const auto& d = c.distortion();
    cs << i + 1 << (d.isZero() ? " PINHOLE " : " OPENCV ") << c.width() << ' ' << c.height() << ' ' << fmt(K(0, 0)) << ' '
       << fmt(K(1, 1)) << ' ' << fmt(K(0, 2) + 0.5) << ' ' << fmt(K(1, 2) + 0.5);
    if (!d.isZero()) cs << ' ' << fmt(d.k1) << ' ' << fmt(d.k2) << ' ' << fmt(d.p1) << ' ' << fmt(d.p2);
    cs << "\n";
    const Eigen::Quaterniond q(c.R());
    std::string name = c.name().empty() ? "image" + std::to_string(i) : c.name();
    for (char& ch : name)
      if (std::isspace(static_cast<unsigned char>(ch))) ch = '_';
    is << i + 1 << ' ' << fmt(q.w()) << ' ' << fmt(q.x()) << ' ' << fmt(q.y()) << ' ' << fmt(q.z()) << ' ' << fmt(c.t().x())
       << ' ' << fmt(c.t().y()) << ' ' << fmt(c.t().z()) << ' ' << i + 1 << ' ' << name << "\n\n";
  }
  write_text_file_atomic((fs::path(dir) / "cameras.txt").string(), cs.str());
  write_text_file_atomic((fs::path(dir) / "images.txt").string(), is.str());
}

Camera read_projection_matrix(const std::string& path, int width, int height, const std::string& name) {
  // XML tags (and the <?xml ...?> declaration) become blanks; newlines stay for line numbers.
  std::string text = detail::TextBuffer::load(path).data();
  bool in_tag = false;
  for (char& ch : text) {
    if (ch == '<') in_tag = true;
    if (in_tag) {
      if (ch == '>') in_tag = false;
      if (ch != '\n') ch = ' ';
    }
  }
  detail::TextBuffer tb(path, text);
  std::vector<double> v;
  int first_line = 0;
  std::string_view tok;
  while (tb.token(tok, true)) {
    if (tok == "CONTOUR" && v.empty()) continue;
    double x;
    if (!detail::parse_double(tok, x))
      tb.fail("'" + std::string(tok) + "' is not a number; a projection-matrix file holds 12 numbers (3x4, row-major)");
    if (!std::isfinite(x)) tb.fail("P entry " + std::to_string(v.size() + 1) + " is not finite");
    if (v.empty()) first_line = tb.line();
    v.push_back(x);
  }
  if (v.size() != 12)
    throw FileError(path + ": found " + std::to_string(v.size()) + " numbers, a 3x4 projection matrix needs exactly 12");
  Matrix34d P;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) P(r, c) = v[4 * r + c];
  return checked_camera(tb, first_line, [&] {
    return Camera::fromProjection(name.empty() ? fs::path(path).stem().string() : name, width, height, P);
  });
}

void write_projection_matrix(const std::string& path, const Camera& c) {
  if (!c.distortion().isZero())
    throw InvalidInput("[tbsp::write_projection_matrix] camera '" + c.name() + "' has lens distortion, which a 3x4 P cannot store");
  const Matrix34d P = c.P();
  std::ostringstream os;
  os << "# 3x4 projection matrix P = K[R|t] of camera '" << c.name() << "' (" << c.width() << "x" << c.height() << "), pixels\n";
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 4; ++k) os << (k ? " " : "") << fmt(P(r, k));
    os << "\n";
  }
  write_text_file_atomic(path, os.str());
}

RectifiedPairCalibration read_middlebury_stereo_calib(const std::string& path) {
  auto tb = detail::TextBuffer::load(path);
  RectifiedPairCalibration c;
  bool have_cam0 = false, have_cam1 = false, have_baseline = false, have_doffs = false;
  double f1 = 0, cy1 = 0;
  std::map<std::string, int> seen;
  std::string_view line;
  while (tb.nextLine(line)) {
    const int ln = tb.line() - 1;
    auto fail = [&](const std::string& m) -> void { throw FileError(path + ":" + std::to_string(ln) + ": " + m); };
    std::string l(line);
    const auto first = l.find_first_not_of(" \t");
    if (first == std::string::npos || l[first] == '#') continue;
    const auto eq = l.find('=');
    if (eq == std::string::npos) fail("expected 'key=value' (Middlebury calib.txt), got '" + l.substr(0, 60) + "'");
    std::string key = l.substr(0, eq), value = l.substr(eq + 1);
    key.erase(0, key.find_first_not_of(" \t"));
    key.erase(key.find_last_not_of(" \t") + 1);
    if (seen[key]++) fail("key '" + key + "' appears twice");
    if (key == "cam0" || key == "cam1") {
      const auto a = value.find('['), b = value.rfind(']');
      if (a == std::string::npos || b == std::string::npos || b < a) fail(key + ": expected a matrix in brackets, [f 0 cx; 0 f cy; 0 0 1]");
      std::string inner = value.substr(a + 1, b - a - 1);
      int rows = 1;
      for (char& ch : inner)
        if (ch == ';') {
          ch = ' ';
          ++rows;
        }
      std::istringstream is(inner);
      std::vector<double> v;
      std::string tok;
      while (is >> tok) {
        double x;
        if (!detail::parse_double(tok, x) || !std::isfinite(x)) fail(key + ": '" + tok.substr(0, 30) + "' is not a number");
        v.push_back(x);
      }
      if (rows != 3 || v.size() != 9) fail(key + ": expected 3 rows of 3 numbers separated by ';', got " + std::to_string(v.size()) + " numbers");
      if (!(v[0] > 0) || std::abs(v[0] - v[4]) > 1e-6 * v[0] || v[1] != 0 || v[3] != 0 || v[6] != 0 || v[7] != 0 || v[8] != 1)
        fail(key + ": expected [f 0 cx; 0 f cy; 0 0 1] with f > 0 (a rectified pair's intrinsics)");
      if (key == "cam0") {
        c.f = v[0];
        c.cx0 = v[2];
        c.cy = v[5];
        have_cam0 = true;
      } else {
        f1 = v[0];
        c.cx1 = v[2];
        cy1 = v[5];
        have_cam1 = true;
      }
      continue;
    }
    double x;
    std::string vt = value;
    vt.erase(0, vt.find_first_not_of(" \t"));
    vt.erase(vt.find_last_not_of(" \t\r") + 1);
    if (!detail::parse_double(vt, x) || !std::isfinite(x)) fail(key + ": '" + vt.substr(0, 30) + "' is not a number");
    auto as_int = [&](int& out) {
      if (x < 0 || x > 1e6 || x != std::floor(x)) fail(key + " must be a non-negative integer, got " + vt.substr(0, 30));
      out = static_cast<int>(x);
    };
    if (key == "doffs") {
      c.doffs = x;
      have_doffs = true;
    } else if (key == "baseline") {
      if (!(x > 0)) fail("baseline must be > 0, got " + vt.substr(0, 30));
      c.baseline = x;
      have_baseline = true;
    } else if (key == "width") {
      as_int(c.width);
    } else if (key == "height") {
      as_int(c.height);
    } else if (key == "ndisp") {
      as_int(c.ndisp);
    } else if (key != "vmin" && key != "vmax" && key != "isint" && key != "dyavg" && key != "dymax") {
      fail("unknown key '" + key.substr(0, 30) + "' (Middlebury calib.txt keys: cam0 cam1 doffs baseline width height ndisp vmin vmax isint dyavg dymax)");
    }
  }
  if (!have_cam0 || !have_cam1 || !have_baseline)
    throw FileError(path + ": missing " + std::string(!have_cam0 ? "cam0" : (!have_cam1 ? "cam1" : "baseline")) +
                    " (a Middlebury calib.txt needs cam0, cam1 and baseline)");
  if (std::abs(f1 - c.f) > 1e-6 * c.f || std::abs(cy1 - c.cy) > 1e-6 * std::max(1.0, std::abs(c.cy)))
    throw FileError(path + ": cam0 and cam1 differ in f or cy: the pair is not rectified");
  if (!have_doffs) c.doffs = c.cx1 - c.cx0;
  if (std::abs(c.doffs - (c.cx1 - c.cx0)) > 0.01)
    throw FileError(path + ": doffs = " + std::to_string(c.doffs) + " but cx1 - cx0 = " + std::to_string(c.cx1 - c.cx0) +
                    ": fix doffs or the principal points");
  return c;
}

}  // namespace tbsp
