#include "tbsp/io/studio.h"

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <set>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>  // the CAP_PROP_* ids only: videos are read through video_reader.h
#include <yaml-cpp/yaml.h>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "video_reader.h"

namespace fs = std::filesystem;

namespace tbsp {

// ------------------------------------------------------------------------------- patterns
std::string expand_frame_pattern(const std::string& pat, int frame) {
  std::string out;
  int directives = 0;
  for (std::size_t i = 0; i < pat.size(); ++i) {
    if (pat[i] != '%') { out += pat[i]; continue; }
    if (i + 1 < pat.size() && pat[i + 1] == '%') { out += '%'; ++i; continue; }
    std::size_t j = i + 1;
    int width = 0;
    bool zero = false;
    if (j < pat.size() && pat[j] == '0') { zero = true; ++j; }
    if (j < pat.size() && std::isdigit(static_cast<unsigned char>(pat[j]))) { width = pat[j] - '0'; ++j; }
    if (j >= pat.size() || pat[j] != 'd' || (zero && width == 0))
      throw InvalidInput("frame pattern '" + pat + "': only %d or %0Nd (N = 1..9) may follow '%' (write %% for a literal %)");
    std::ostringstream os;
    if (frame < 0) os << '-';
    os << std::setw(width) << std::setfill(zero ? '0' : ' ') << std::abs(frame);
    out += os.str();
    ++directives;
    i = j;
  }
  if (directives != 1)
    throw InvalidInput("frame pattern '" + pat + "' must contain exactly one %d or %0Nd for the frame number (found " +
                       std::to_string(directives) + ")");
  return out;
}

std::vector<Camera> Studio::cameraList() const {
  std::vector<Camera> c;
  for (const auto& s : cameras) c.push_back(s.camera);
  return c;
}
std::string Studio::resolve(const std::string& rel) const {
  if (rel.empty() || fs::path(rel).is_absolute()) return rel;
  return (fs::path(path).parent_path() / rel).string();
}
std::string Studio::imagePath(int c, int f) const { return resolve(expand_frame_pattern(cameras.at(c).images, f)); }
std::string Studio::silhouettePath(int c, int f) const { return resolve(expand_frame_pattern(cameras.at(c).silhouettes, f)); }
std::string Studio::groundTruthPath(int f) const { return resolve(expand_frame_pattern(ground_truth, f)); }

// ------------------------------------------------------------------------------- reading
namespace {

struct StudioCtx {
  std::string path;
  [[noreturn]] void fail(const YAML::Node& n, const std::string& msg) const {
    const int line = n.Mark().line >= 0 ? n.Mark().line + 1 : 0;
    throw FileError(path + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": " + msg);
  }
  YAML::Node need(const YAML::Node& parent, const std::string& key, const std::string& where) const {
    if (!parent.IsMap())
      fail(parent, where + " must be a mapping with the key '" + key + "' (e.g. frames: {first: 0, last: 9})");
    YAML::Node n = parent[key];
    if (!n) fail(parent, where + ": the key '" + key + "' is missing");
    return n;
  }
  double number(const YAML::Node& n, const std::string& what) const {
    if (!n.IsScalar()) fail(n, what + " must be a number");
    double v;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      fail(n, what + ": '" + n.Scalar() + "' is not a number");
    }
    if (!std::isfinite(v)) fail(n, what + " is not finite");
    return v;
  }
  int integer(const YAML::Node& n, const std::string& what) const {
    const double v = number(n, what);
    if (v != std::floor(v) || std::abs(v) > 1e9) fail(n, what + ": '" + n.Scalar() + "' is not an integer");
    return static_cast<int>(v);
  }
  std::string string(const YAML::Node& n, const std::string& what) const {
    if (!n.IsScalar()) fail(n, what + " must be a string");
    return n.Scalar();
  }
  std::vector<double> numbers(const YAML::Node& n, std::size_t count, const std::string& what) const {
    std::vector<double> out;
    if (!n.IsSequence()) fail(n, what + " must be a list of " + std::to_string(count) + " numbers");
    for (const auto& e : n) {
      if (e.IsSequence()) {
        for (const auto& x : e) out.push_back(number(x, what));
      } else {
        out.push_back(number(e, what));
      }
    }
    if (out.size() != count) fail(n, what + " must have " + std::to_string(count) + " numbers, found " + std::to_string(out.size()));
    return out;
  }
  std::string pattern(const YAML::Node& n, const std::string& what) const {
    const std::string p = string(n, what);
    try {
      expand_frame_pattern(p, 0);
    } catch (const InvalidInput& e) {
      fail(n, what + ": " + e.what());
    }
    return p;
  }
};

}  // namespace

namespace {
Studio read_studio_file(const std::string& path);
}

Studio read_studio(const std::string& path) {
  try {
    return read_studio_file(path);
  } catch (const YAML::Exception& e) {
    // safety net: a node of an unexpected kind that no check above names
    const int line = e.mark.line >= 0 ? e.mark.line + 1 : 0;
    throw FileError(path + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": unexpected YAML structure (" + e.msg +
                    "); see docs/studio_format.md");
  }
}

namespace {
Studio read_studio_file(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw FileError("'" + path + "': no such file; check the path");
  if (fs::is_directory(path, ec)) {
    if (fs::exists(fs::path(path) / "studio.yaml")) return read_studio_file((fs::path(path) / "studio.yaml").string());
    throw FileError("'" + path + "': is a directory without studio.yaml");
  }
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::ParserException& e) {
    throw FileError(path + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg);
  } catch (const YAML::Exception& e) {
    throw FileError(path + ": cannot read: " + e.what());
  }
  StudioCtx c{path};
  if (!root.IsMap()) throw FileError(path + ": not a studio file: expected a YAML mapping with 'tbsp_studio: 1'");
  const YAML::Node ver = root["tbsp_studio"];
  if (!ver) c.fail(root, "not a tbsp studio file: the key 'tbsp_studio: 1' (format version) is missing");
  if (c.integer(ver, "tbsp_studio") != 1) c.fail(ver, "format version " + ver.Scalar() + " is not supported (this tbsp reads version 1)");
  Studio s;
  s.path = path;
  if (root["name"]) s.name = c.string(root["name"], "name");
  if (root["frame_rate"]) {
    s.frame_rate = c.number(root["frame_rate"], "frame_rate");
    if (!(s.frame_rate > 0)) c.fail(root["frame_rate"], "frame_rate must be positive");
  }
  const YAML::Node frames = c.need(root, "frames", "studio");
  s.first_frame = c.integer(c.need(frames, "first", "frames"), "frames.first");
  s.last_frame = c.integer(c.need(frames, "last", "frames"), "frames.last");
  if (s.last_frame < s.first_frame)
    c.fail(frames, "frames: last (" + std::to_string(s.last_frame) + ") < first (" + std::to_string(s.first_frame) + "): empty frame range");
  const YAML::Node cams = c.need(root, "cameras", "studio");
  if (!cams.IsSequence() || cams.size() == 0) c.fail(cams, "cameras must be a non-empty list");
  std::set<std::string> names;
  for (std::size_t i = 0; i < cams.size(); ++i) {
    const YAML::Node cn = cams[i];
    if (!cn.IsMap()) c.fail(cn, "camera " + std::to_string(i) + " must be a mapping");
    const std::string name = cn["name"] ? c.string(cn["name"], "camera name") : "cam" + std::to_string(i);
    const std::string where = "camera '" + name + "'";
    if (!names.insert(name).second) c.fail(cn, where + ": duplicate camera name");
    const int w = c.integer(c.need(cn, "width", where), where + " width");
    const int h = c.integer(c.need(cn, "height", where), where + " height");
    if (w <= 0 || h <= 0 || w > 100000 || h > 100000) c.fail(cn, where + ": image size " + std::to_string(w) + "x" + std::to_string(h) + " is not plausible");
    StudioCamera sc;
    try {
      if (cn["P"]) {
        if (cn["K"] || cn["R"] || cn["t"]) c.fail(cn, where + ": give either P or K, R, t, not both");
        const auto p = c.numbers(cn["P"], 12, where + " P");
        Matrix34d P;
        for (int r = 0; r < 3; ++r)
          for (int k = 0; k < 4; ++k) P(r, k) = p[static_cast<std::size_t>(4 * r + k)];
        sc.camera = Camera::fromProjection(name, w, h, P);
      } else {
        const auto k = c.numbers(c.need(cn, "K", where + " (or give P)"), 9, where + " K");
        const auto r = c.numbers(c.need(cn, "R", where), 9, where + " R");
        const auto t = c.numbers(c.need(cn, "t", where), 3, where + " t");
        Distortion d;
        if (cn["distortion"]) {
          const YAML::Node dn = cn["distortion"];
          std::vector<double> dv;
          if (!dn.IsSequence() || dn.size() < 1 || dn.size() > 5) c.fail(dn, where + " distortion must be a list of 1 to 5 numbers (k1 k2 p1 p2 k3)");
          for (const auto& e : dn) dv.push_back(c.number(e, where + " distortion"));
          dv.resize(5, 0.0);
          d = {dv[0], dv[1], dv[2], dv[3], dv[4]};
        }
        Eigen::Matrix3d K, R;
        K << k[0], k[1], k[2], k[3], k[4], k[5], k[6], k[7], k[8];
        R << r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8];
        sc.camera = Camera(name, w, h, K, R, Eigen::Vector3d(t[0], t[1], t[2]), d);
      }
    } catch (const FileError&) {
      throw;
    } catch (const InvalidInput& e) {
      c.fail(cn, e.what());
    }
    if (cn["images"]) sc.images = c.pattern(cn["images"], where + " images");
    if (cn["video"]) sc.video = c.string(cn["video"], where + " video");
    if (cn["silhouettes"]) sc.silhouettes = c.pattern(cn["silhouettes"], where + " silhouettes");
    if (!sc.images.empty() && !sc.video.empty()) c.fail(cn, where + ": give either images or video, not both");
    s.cameras.push_back(std::move(sc));
  }
  if (root["template"]) s.template_mesh = c.string(root["template"], "template");
  if (root["markers"]) s.markers = c.string(root["markers"], "markers");
  if (root["skeleton"]) s.skeleton = c.string(root["skeleton"], "skeleton");
  if (root["ground_truth"]) s.ground_truth = c.pattern(root["ground_truth"], "ground_truth");
  static const std::set<std::string> known = {"tbsp_studio", "name", "frame_rate", "frames", "cameras",
                                              "template", "markers", "skeleton", "ground_truth"};
  for (const auto& kv : root) {
    if (!kv.first.IsScalar()) c.fail(kv.first, "keys must be plain names");
    const std::string key = kv.first.Scalar();
    if (!known.count(key)) c.fail(kv.first, "unknown key '" + key + "' (known: tbsp_studio, name, frame_rate, frames, cameras, template, markers, skeleton, ground_truth)");
  }
  return s;
}
}  // namespace

void write_studio(const std::string& path, const Studio& s) {
  YAML::Emitter e;
  e.SetDoublePrecision(17);
  e << YAML::BeginMap;
  e << YAML::Key << "tbsp_studio" << YAML::Value << 1;
  if (!s.name.empty()) e << YAML::Key << "name" << YAML::Value << s.name;
  e << YAML::Key << "frame_rate" << YAML::Value << s.frame_rate;
  e << YAML::Key << "frames" << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "first" << YAML::Value << s.first_frame
    << YAML::Key << "last" << YAML::Value << s.last_frame << YAML::EndMap;
  e << YAML::Key << "cameras" << YAML::Value << YAML::BeginSeq;
  for (const auto& sc : s.cameras) {
    const Camera& c = sc.camera;
    e << YAML::BeginMap << YAML::Key << "name" << YAML::Value << c.name() << YAML::Key << "width" << YAML::Value << c.width()
      << YAML::Key << "height" << YAML::Value << c.height();
    auto mat = [&](const char* key, const auto& M) {
      e << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginSeq;
      for (int r = 0; r < M.rows(); ++r)
        for (int k = 0; k < M.cols(); ++k) e << M(r, k);
      e << YAML::EndSeq;
    };
    mat("K", c.K());
    mat("R", c.R());
    mat("t", c.t().transpose());
    if (!c.distortion().isZero()) {
      const auto& d = c.distortion();
      e << YAML::Key << "distortion" << YAML::Value << YAML::Flow << YAML::BeginSeq << d.k1 << d.k2 << d.p1 << d.p2 << d.k3 << YAML::EndSeq;
    }
    if (!sc.images.empty()) e << YAML::Key << "images" << YAML::Value << sc.images;
    if (!sc.video.empty()) e << YAML::Key << "video" << YAML::Value << sc.video;
    if (!sc.silhouettes.empty()) e << YAML::Key << "silhouettes" << YAML::Value << sc.silhouettes;
    e << YAML::EndMap;
  }
  e << YAML::EndSeq;
  if (!s.template_mesh.empty()) e << YAML::Key << "template" << YAML::Value << s.template_mesh;
  if (!s.markers.empty()) e << YAML::Key << "markers" << YAML::Value << s.markers;
  if (!s.skeleton.empty()) e << YAML::Key << "skeleton" << YAML::Value << s.skeleton;
  if (!s.ground_truth.empty()) e << YAML::Key << "ground_truth" << YAML::Value << s.ground_truth;
  e << YAML::EndMap;
  if (!e.good()) throw InvalidInput(std::string("[tbsp::write_studio] cannot emit YAML: ") + e.GetLastError());
  write_text_file_atomic(path, std::string("# tbsp studio dataset, format: docs/studio_format.md\n") + e.c_str() + "\n");
}

// ------------------------------------------------------------------------------- checking
std::string StudioCheck::summary() const {
  std::ostringstream os;
  os << files_checked << " files checked, " << files_missing << " missing";
  if (!missing.empty()) {
    os << ":";
    for (const auto& m : missing) os << "\n  missing: " << m;
    if (files_missing > static_cast<int>(missing.size())) os << "\n  ... and " << files_missing - static_cast<int>(missing.size()) << " more";
  }
  for (const auto& p : problems) os << "\n  problem: " << p;
  return os.str();
}

StudioCheck check_studio(const Studio& s, int max_listed) {
  StudioCheck r;
  auto exists = [&](const std::string& f) {
    ++r.files_checked;
    std::error_code ec;
    if (fs::exists(f, ec)) return true;
    ++r.files_missing;
    if (static_cast<int>(r.missing.size()) < max_listed) r.missing.push_back(f);
    return false;
  };
  for (const std::string* opt : {&s.template_mesh, &s.markers, &s.skeleton})
    if (!opt->empty()) exists(s.resolve(*opt));
  for (int ci = 0; ci < static_cast<int>(s.cameras.size()); ++ci) {
    const StudioCamera& sc = s.cameras[ci];
    const std::string cname = "camera '" + sc.camera.name() + "'";
    auto check_size = [&](const std::string& f, int flags, const char* what) {
      cv::Mat m = cv::imread(f, flags);
      if (m.empty()) r.problems.push_back(cname + ": " + what + " '" + f + "' cannot be decoded");
      else if (m.cols != sc.camera.width() || m.rows != sc.camera.height())
        r.problems.push_back(cname + ": " + what + " '" + f + "' is " + std::to_string(m.cols) + "x" + std::to_string(m.rows) +
                             ", the calibration says " + std::to_string(sc.camera.width()) + "x" + std::to_string(sc.camera.height()));
    };
    if (!sc.images.empty()) {
      bool first = true;
      for (int f = s.first_frame; f <= s.last_frame; ++f) {
        const std::string p = s.imagePath(ci, f);
        if (exists(p) && first) { check_size(p, cv::IMREAD_COLOR, "image"); first = false; }
      }
    }
    if (!sc.video.empty()) {
      const std::string v = s.resolve(sc.video);
      if (exists(v)) {
        detail::VideoReader cap;
        std::string why;
        try {
          if (!cap.open(v)) why = " cannot be opened by OpenCV";
        } catch (const FileError& e) {  // the video module is missing: an installation problem, listed
          why = std::string(": ") + e.what();
        }
        if (!why.empty()) {
          r.problems.push_back(cname + ": video '" + v + "'" + why);
        } else {
          const double n = cap.get(cv::CAP_PROP_FRAME_COUNT);
          if (n > 0 && n < s.numFrames())
            r.problems.push_back(cname + ": video '" + v + "' has " + std::to_string(static_cast<long long>(n)) + " frames, the studio needs " + std::to_string(s.numFrames()));
          const int w = static_cast<int>(cap.get(cv::CAP_PROP_FRAME_WIDTH)), h = static_cast<int>(cap.get(cv::CAP_PROP_FRAME_HEIGHT));
          if (w != sc.camera.width() || h != sc.camera.height())
            r.problems.push_back(cname + ": video '" + v + "' is " + std::to_string(w) + "x" + std::to_string(h) + ", the calibration says " +
                                 std::to_string(sc.camera.width()) + "x" + std::to_string(sc.camera.height()));
        }
      }
    }
    if (!sc.silhouettes.empty()) {
      bool first = true;
      for (int f = s.first_frame; f <= s.last_frame; ++f) {
        const std::string p = s.silhouettePath(ci, f);
        if (exists(p) && first) { check_size(p, cv::IMREAD_GRAYSCALE, "silhouette"); first = false; }
      }
    }
  }
  if (!s.ground_truth.empty())
    for (int f = s.first_frame; f <= s.last_frame; ++f) exists(s.groundTruthPath(f));
  return r;
}

// ------------------------------------------------------------------------------- streaming
struct StudioFrameStream::Impl {
  Studio studio;
  Options opt;
  int next = 0;
  std::vector<detail::VideoReader> videos;
  std::vector<int> video_pos;  // next frame index each video will deliver
  cv::Mat scratch;
};

StudioFrameStream::StudioFrameStream(const Studio& s, Options o) : impl_(std::make_unique<Impl>()) {
  Impl& d = *impl_;
  d.studio = s;
  if (o.first < 0) o.first = s.first_frame;
  if (o.last < 0) o.last = s.last_frame;
  if (o.step < 1) throw InvalidInput("[tbsp::StudioFrameStream] step must be >= 1");
  if (o.first < s.first_frame || o.last > s.last_frame || o.first > o.last)
    throw InvalidInput("[tbsp::StudioFrameStream] frame range " + std::to_string(o.first) + ".." + std::to_string(o.last) +
                       " is outside the studio's " + std::to_string(s.first_frame) + ".." + std::to_string(s.last_frame));
  d.opt = o;
  d.next = o.first;
  d.videos.resize(s.cameras.size());
  d.video_pos.assign(s.cameras.size(), s.first_frame);
}
StudioFrameStream::~StudioFrameStream() = default;

bool StudioFrameStream::next(StudioFrame& out) {
  Impl& d = *impl_;
  if (d.next > d.opt.last) return false;
  const Studio& s = d.studio;
  const int f = d.next;
  const std::size_t k = s.cameras.size();
  out.frame = f;
  out.images.resize(k);
  out.silhouettes.resize(k);
  for (std::size_t ci = 0; ci < k; ++ci) {
    const StudioCamera& sc = s.cameras[ci];
    const std::string cname = "camera '" + sc.camera.name() + "', frame " + std::to_string(f);
    auto check = [&](const cv::Mat& m, const std::string& file) {
      if (m.cols != sc.camera.width() || m.rows != sc.camera.height())
        throw FileError("'" + file + "' (" + cname + "): size " + std::to_string(m.cols) + "x" + std::to_string(m.rows) +
                        " differs from the calibrated " + std::to_string(sc.camera.width()) + "x" + std::to_string(sc.camera.height()));
    };
    if (d.opt.images && !sc.images.empty()) {
      const std::string p = s.imagePath(static_cast<int>(ci), f);
      if (fs::exists(p)) out.images[ci] = cv::imread(p, cv::IMREAD_COLOR);
      else out.images[ci].release();
      if (out.images[ci].empty())
        throw FileError("'" + p + "' (" + cname + "): " + (fs::exists(p) ? "cannot be decoded" : "missing; run `tbsp replay STUDIO --check` to list every missing frame"));
      check(out.images[ci], p);
    } else if (d.opt.images && !sc.video.empty()) {
      const std::string v = s.resolve(sc.video);
      if (!d.videos[ci].isOpened()) {
        d.videos[ci].open(v);
        if (!d.videos[ci].isOpened()) throw FileError("'" + v + "' (" + cname + "): OpenCV cannot open the video");
      }
      while (d.video_pos[ci] < f) {  // skip frames (sub-range / step)
        if (!d.videos[ci].grab()) throw FileError("'" + v + "' (" + cname + "): the video ends before frame " + std::to_string(f));
        ++d.video_pos[ci];
      }
      if (!d.videos[ci].read(out.images[ci]) || out.images[ci].empty())
        throw FileError("'" + v + "' (" + cname + "): the video ends before this frame");
      ++d.video_pos[ci];
      check(out.images[ci], v);
    } else {
      out.images[ci].release();
    }
    if (d.opt.silhouettes && !sc.silhouettes.empty()) {
      const std::string p = s.silhouettePath(static_cast<int>(ci), f);
      if (fs::exists(p)) d.scratch = cv::imread(p, cv::IMREAD_GRAYSCALE);
      else d.scratch.release();
      if (d.scratch.empty())
        throw FileError("'" + p + "' (" + cname + " silhouette): " + (fs::exists(p) ? "cannot be decoded" : "missing"));
      check(d.scratch, p);
      cv::threshold(d.scratch, out.silhouettes[ci], 127, 255, cv::THRESH_BINARY);
    } else {
      out.silhouettes[ci].release();
    }
  }
  d.next += d.opt.step;
  return true;
}

}  // namespace tbsp
