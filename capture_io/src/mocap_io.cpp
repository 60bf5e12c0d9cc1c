#include "tbsp/io/mocap_io.h"

#include <cmath>
#include <cstring>
#include <iomanip>
#include <functional>
#include <limits>
#include <map>
#include <sstream>

#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/io/atomic_file.h"
#include "text_buffer.h"

namespace tbsp {

int MarkerTrajectories::markerIndex(const std::string& name) const {
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return static_cast<int>(i);
  return -1;
}

// ----------------------------------------------------------------------------------------- TRC
namespace {
std::vector<std::string_view> split_tabs(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t b = 0;
  while (true) {
    const std::size_t e = line.find('\t', b);
    out.push_back(line.substr(b, e == std::string_view::npos ? std::string_view::npos : e - b));
    if (e == std::string_view::npos) break;
    b = e + 1;
  }
  return out;
}
std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}
bool blank(std::string_view s) { return trim(s).empty(); }
}  // namespace

MarkerTrajectories read_trc(const std::string& path) {
  auto tb = detail::TextBuffer::load(path);
  std::string_view line;
  auto need = [&](const char* what) {
    if (!tb.nextLine(line)) tb.fail(std::string("file ends before the ") + what + " (truncated TRC?)");
  };
  need("PathFileType line");
  if (trim(line).rfind("PathFileType", 0) != 0)
    tb.fail("not a TRC file: the first line must start with 'PathFileType' (got '" + std::string(trim(line).substr(0, 40)) + "')");
  need("header names line");
  const auto hnames = split_tabs(line);
  need("header values line");
  const auto hvals = split_tabs(line);
  const int hline = tb.line() - 1;
  auto hvalue = [&](const std::string& key) -> std::string {
    for (std::size_t i = 0; i < hnames.size(); ++i)
      if (trim(hnames[i]) == key) {
        if (i >= hvals.size() || blank(hvals[i])) throw FileError(path + ":" + std::to_string(hline) + ": header value '" + key + "' is empty");
        return std::string(trim(hvals[i]));
      }
    throw FileError(path + ":2: header field '" + key + "' is missing (need DataRate, NumFrames, NumMarkers, Units)");
  };
  MarkerTrajectories m;
  double rate;
  long long nframes, nmarkers;
  if (!detail::parse_double(hvalue("DataRate"), rate) || !(rate > 0) || !std::isfinite(rate))
    throw FileError(path + ":" + std::to_string(hline) + ": DataRate '" + hvalue("DataRate") + "' is not a positive number");
  if (!detail::parse_int(hvalue("NumFrames"), nframes) || nframes < 0 || nframes > 100000000)
    throw FileError(path + ":" + std::to_string(hline) + ": NumFrames '" + hvalue("NumFrames") + "' is not a plausible count");
  if (!detail::parse_int(hvalue("NumMarkers"), nmarkers) || nmarkers <= 0 || nmarkers > 100000)
    throw FileError(path + ":" + std::to_string(hline) + ": NumMarkers '" + hvalue("NumMarkers") + "' is not a plausible count");
  m.frame_rate = rate;
  m.units = hvalue("Units");
  need("marker names line (Frame# Time name ...)");
  const auto names = split_tabs(line);
  if (names.size() < 2 || trim(names[0]) != "Frame#")
    tb.fail("expected the marker name line starting with 'Frame#'");
  for (std::size_t i = 2; i < names.size(); ++i)
    if (!blank(names[i])) m.names.emplace_back(trim(names[i]));
  if (static_cast<long long>(m.names.size()) != nmarkers)
    tb.fail("the header says NumMarkers = " + std::to_string(nmarkers) + " but " + std::to_string(m.names.size()) +
            " marker names follow 'Frame#\tTime'");
  need("coordinate line (X1 Y1 Z1 ...)");
  // Sanity cap before allocating: every frame needs at least a few bytes.
  if (static_cast<std::size_t>(nframes) > tb.remaining())
    tb.fail("NumFrames = " + std::to_string(nframes) + " cannot fit in the remaining " + std::to_string(tb.remaining()) + " bytes");
  m.data.setConstant(nframes, 3 * nmarkers, std::numeric_limits<double>::quiet_NaN());
  long long row = 0, residue = 0;
  while (tb.nextLine(line)) {
    if (blank(line)) continue;
    const auto cells = split_tabs(line);
    if (blank(cells[0])) {  // no frame number: not a data row
      ++residue;
      continue;
    }
    if (row >= nframes) tb.fail("more data rows than NumFrames = " + std::to_string(nframes));
    long long fno;
    if (!detail::parse_int(trim(cells[0]), fno)) tb.fail("frame number '" + std::string(trim(cells[0])) + "' is not an integer");
    if (row == 0) m.first_frame = static_cast<int>(fno);
    if (cells.size() > 2 + 3 * static_cast<std::size_t>(nmarkers)) {
      for (std::size_t i = 2 + 3 * nmarkers; i < cells.size(); ++i)
        if (!blank(cells[i])) tb.fail("row has more values than 3 x NumMarkers = " + std::to_string(3 * nmarkers));
    }
    for (std::size_t i = 2; i < cells.size() && i < 2 + 3 * static_cast<std::size_t>(nmarkers); ++i) {
      const auto c = trim(cells[i]);
      if (c.empty()) continue;
      double v;
      if (!detail::parse_double(c, v)) tb.fail("value '" + std::string(c) + "' (marker '" + m.names[(i - 2) / 3] + "') is not a number");
      if (!std::isfinite(v)) tb.fail("value of marker '" + m.names[(i - 2) / 3] + "' is NaN/Inf; leave the cell empty for a gap");
      m.data(row, static_cast<Eigen::Index>(i - 2)) = v;
    }
    ++row;
  }
  if (residue > 0) logger()->warn("{}: ignored {} row(s) without a frame number", path, residue);
  if (row != nframes)
    throw FileError(path + ": the header says NumFrames = " + std::to_string(nframes) + " but " + std::to_string(row) +
                    " data rows were found (truncated file?)");
  // A marker is valid only with all three coordinates.
  for (Eigen::Index f = 0; f < m.data.rows(); ++f)
    for (long long k = 0; k < nmarkers; ++k)
      if (!m.data.block<1, 3>(f, 3 * k).allFinite()) m.data.block<1, 3>(f, 3 * k).setConstant(std::numeric_limits<double>::quiet_NaN());
  return m;
}

void write_trc(const std::string& path, const MarkerTrajectories& m) {
  if (m.data.cols() != 3 * m.numMarkers())
    throw InvalidInput("[tbsp::write_trc] data has " + std::to_string(m.data.cols()) + " columns for " +
                       std::to_string(m.numMarkers()) + " markers (need 3 per marker)");
  if (!(m.frame_rate > 0)) throw InvalidInput("[tbsp::write_trc] frame_rate must be positive");
  for (const auto& n : m.names)
    if (n.empty() || n.find_first_of("\t\n\r") != std::string::npos)
      throw InvalidInput("[tbsp::write_trc] marker names must be non-empty without tabs or newlines");
  std::ostringstream os;
  os << std::setprecision(10);
  const std::string fname = path.substr(path.find_last_of('/') + 1);
  os << "PathFileType\t4\t(X/Y/Z)\t" << fname << "\n";
  os << "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n";
  os << m.frame_rate << '\t' << m.frame_rate << '\t' << m.numFrames() << '\t' << m.numMarkers() << '\t'
     << (m.units.empty() ? "m" : m.units) << '\t' << m.frame_rate << '\t' << m.first_frame << '\t' << m.numFrames() << "\n";
  os << "Frame#\tTime";
  for (const auto& n : m.names) os << '\t' << n << "\t\t";
  os << "\n\t";
  for (int k = 0; k < m.numMarkers(); ++k) os << "\tX" << k + 1 << "\tY" << k + 1 << "\tZ" << k + 1;
  os << "\n\n";
  for (int f = 0; f < m.numFrames(); ++f) {
    os << m.first_frame + f << '\t' << f / m.frame_rate;
    for (int k = 0; k < m.numMarkers(); ++k) {
      if (!m.valid(f, k)) { os << "\t\t\t"; continue; }
      for (int d = 0; d < 3; ++d) os << '\t' << m.data(f, 3 * k + d);
    }
    os << "\n";
  }
  write_text_file_atomic(path, os.str());
}

// ----------------------------------------------------------------------------------------- C3D
namespace {

class C3dReader {
public:
  explicit C3dReader(detail::TextBuffer& tb) : tb_(tb), d_(tb.data()) {}
  [[noreturn]] void fail(std::size_t at, const std::string& msg) const {
    throw FileError(tb_.path() + " (byte " + std::to_string(at) + "): " + msg);
  }
  void need(std::size_t at, std::size_t n, const char* what) const {
    if (at + n > d_.size() || at + n < at)
      fail(at, std::string("file ends inside the ") + what + " (needs " + std::to_string(n) + " bytes; file has " +
                   std::to_string(d_.size()) + "); truncated C3D?");
  }
  std::uint8_t u8(std::size_t at, const char* what) const { need(at, 1, what); return static_cast<std::uint8_t>(d_[at]); }
  std::int8_t i8(std::size_t at, const char* what) const { return static_cast<std::int8_t>(u8(at, what)); }
  std::uint16_t u16(std::size_t at, const char* what) const {
    need(at, 2, what);
    std::uint16_t v;
    std::memcpy(&v, d_.data() + at, 2);
    return v;
  }
  std::int16_t i16(std::size_t at, const char* what) const { return static_cast<std::int16_t>(u16(at, what)); }
  float f32(std::size_t at, const char* what) const {
    need(at, 4, what);
    float v;
    std::memcpy(&v, d_.data() + at, 4);
    return v;
  }
  std::size_t size() const { return d_.size(); }

private:
  detail::TextBuffer& tb_;
  const std::string& d_;
};

struct C3dParam {
  int type = 0;  // -1 char, 1 byte, 2 int16, 4 float
  std::vector<int> dims;
  std::size_t data_at = 0;
  std::size_t count() const {
    std::size_t n = 1;
    for (int d : dims) n *= static_cast<std::size_t>(d);
    return n;
  }
};

}  // namespace

MarkerTrajectories read_c3d(const std::string& path, bool allow_truncated) {
  auto tb = detail::TextBuffer::load(path);
  C3dReader r(tb);
  if (r.size() < 512) r.fail(0, "file is " + std::to_string(r.size()) + " bytes, shorter than the 512-byte C3D header");
  const int pblock = r.u8(0, "header");
  if (r.u8(1, "header") != 0x50)
    r.fail(1, "wrong magic byte " + std::to_string(r.u8(1, "header")) + " (C3D files have 0x50 at byte 1); not a C3D file");
  if (pblock < 2) r.fail(0, "parameter section block " + std::to_string(pblock) + " is invalid (must be >= 2)");
  const std::size_t pstart = static_cast<std::size_t>(pblock - 1) * 512;
  const int processor = r.u8(pstart + 3, "parameter section header");
  if (processor == 85) r.fail(pstart + 3, "DEC (VAX) processor format is not supported; re-export the file as Intel (PC) C3D, e.g. with ezc3d or Mokka");
  if (processor == 86) r.fail(pstart + 3, "MIPS (big-endian) processor format is not supported; re-export the file as Intel (PC) C3D");
  if (processor != 84) r.fail(pstart + 3, "unknown processor type " + std::to_string(processor) + " (84 = Intel, 85 = DEC, 86 = MIPS)");

  MarkerTrajectories m;
  const int npoints = r.u16(2, "header");
  const int nanalog = r.u16(4, "header");
  const int first = r.u16(6, "header");
  const int last = r.u16(8, "header");
  const float scale = r.f32(12, "header");
  int data_block = r.u16(16, "header");
  const float hrate = r.f32(20, "header");
  m.first_frame = first;
  m.analog_per_frame = nanalog;
  if (!std::isfinite(scale) || scale == 0) r.fail(12, "point scale factor is 0 or not finite");

  // Parameters: group id -> name; (GROUP:PARAM) -> description of its data.
  std::map<int, std::string> groups;
  std::map<std::string, C3dParam> params;
  std::size_t at = pstart + 4;
  const std::size_t pend = pstart + static_cast<std::size_t>(std::max<int>(1, r.u8(pstart + 2, "parameter header"))) * 512;
  std::vector<std::pair<int, std::pair<std::string, C3dParam>>> pending;
  for (int guard = 0; guard < 100000; ++guard) {
    if (at >= r.size() || at >= pend) break;
    const int nch = std::abs(static_cast<int>(r.i8(at, "parameter record")));
    if (nch == 0) break;
    const int id = r.i8(at + 1, "parameter record");
    r.need(at + 2, static_cast<std::size_t>(nch) + 2, "parameter name");
    std::string name = tb.data().substr(at + 2, static_cast<std::size_t>(nch));
    for (char& ch : name) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    const std::size_t off_at = at + 2 + static_cast<std::size_t>(nch);
    const int next = r.i16(off_at, "parameter record");
    if (id < 0) {
      groups[-id] = name;
    } else if (id > 0) {
      C3dParam p;
      std::size_t q = off_at + 2;
      p.type = r.i8(q, "parameter type");
      if (p.type != -1 && p.type != 1 && p.type != 2 && p.type != 4)
        r.fail(q, "parameter '" + name + "' has invalid type " + std::to_string(p.type) + " (must be -1, 1, 2 or 4)");
      const int nd = r.u8(q + 1, "parameter dimensions");
      if (nd > 7) r.fail(q + 1, "parameter '" + name + "' has " + std::to_string(nd) + " dimensions (at most 7)");
      for (int k = 0; k < nd; ++k) p.dims.push_back(r.u8(q + 2 + k, "parameter dimensions"));
      p.data_at = q + 2 + nd;
      r.need(p.data_at, p.count() * static_cast<std::size_t>(std::abs(p.type)), "parameter data");
      pending.push_back({id, {name, p}});
    }
    if (next == 0) break;
    if (next < 0) r.fail(off_at, "negative offset to the next parameter record");
    at = off_at + static_cast<std::size_t>(next);
  }
  for (auto& [gid, np] : pending) {
    auto g = groups.find(gid);
    if (g != groups.end()) params[g->second + ":" + np.first] = np.second;
  }
  auto find = [&](const std::string& key) -> const C3dParam* {
    auto it = params.find(key);
    return it == params.end() ? nullptr : &it->second;
  };
  auto param_number = [&](const std::string& key, double fallback) {
    const C3dParam* p = find(key);
    if (!p || p->count() < 1) return fallback;
    double v = fallback;
    if (p->type == 2) v = static_cast<double>(r.i16(p->data_at, "parameter data"));
    if (p->type == 4) v = static_cast<double>(r.f32(p->data_at, "parameter data"));
    if (p->type == 1) v = static_cast<double>(r.u8(p->data_at, "parameter data"));
    // the callers convert to int: a float parameter must be a finite number in int range
    if (!std::isfinite(v) || std::abs(v) > 2e9)
      r.fail(p->data_at, "parameter " + key + " = " + std::to_string(v) + " is out of range");
    return v;
  };
  auto param_strings = [&](const std::string& key) {
    std::vector<std::string> out;
    const C3dParam* p = find(key);
    if (!p || p->type != -1 || p->dims.empty()) return out;
    const std::size_t len = static_cast<std::size_t>(p->dims[0]);
    const std::size_t n = p->dims.size() >= 2 ? static_cast<std::size_t>(p->dims[1]) : 1;
    for (std::size_t i = 0; i < n; ++i) {
      std::string s = tb.data().substr(p->data_at + i * len, len);
      while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
      std::size_t b = 0;
      while (b < s.size() && s[b] == ' ') ++b;
      out.push_back(s.substr(b));
    }
    return out;
  };

  const double rate = param_number("POINT:RATE", hrate);
  m.frame_rate = rate;
  if (!(m.frame_rate > 0) || !std::isfinite(m.frame_rate)) r.fail(20, "frame rate is not a positive number");
  auto units = param_strings("POINT:UNITS");
  m.units = units.empty() ? "" : units[0];
  const int used = static_cast<int>(param_number("POINT:USED", npoints));
  if (used != npoints) r.fail(2, "header says " + std::to_string(npoints) + " points but POINT:USED says " + std::to_string(used));
  const double pdata = param_number("POINT:DATA_START", data_block);
  if (pdata > 0) data_block = static_cast<int>(pdata);
  std::vector<std::string> labels = param_strings("POINT:LABELS");
  for (int k = 2; static_cast<int>(labels.size()) < npoints && k < 100; ++k) {
    auto more = param_strings("POINT:LABELS" + std::to_string(k));
    if (more.empty()) break;
    labels.insert(labels.end(), more.begin(), more.end());
  }
  labels.resize(static_cast<std::size_t>(npoints));
  for (int i = 0; i < npoints; ++i)
    if (labels[i].empty()) labels[i] = "M" + std::to_string(i + 1);
  m.names = labels;

  long long nframes = static_cast<long long>(last) - first + 1;
  const double pframes = param_number("POINT:FRAMES", 0);
  if (pframes < 0) nframes = std::max<long long>(nframes, static_cast<long long>(pframes) + 65536);  // unsigned stored as int16
  else if (pframes > nframes) nframes = static_cast<long long>(pframes);
  if (nframes <= 0) r.fail(6, "frame range " + std::to_string(first) + ".." + std::to_string(last) + " is empty");
  if (data_block < 2) r.fail(16, "data section block " + std::to_string(data_block) + " is invalid");
  const std::size_t word = scale < 0 ? 4 : 2;
  const std::size_t frame_bytes = (static_cast<std::size_t>(npoints) * 4 + static_cast<std::size_t>(nanalog)) * word;
  const std::size_t dstart = static_cast<std::size_t>(data_block - 1) * 512;
  if (frame_bytes == 0) r.fail(2, "no points and no analog data: nothing to read");
  const std::size_t available = dstart > r.size() ? 0 : (r.size() - dstart) / frame_bytes;
  if (allow_truncated && available < static_cast<std::size_t>(nframes) && available > 0) {
    logger()->warn("{}: declares {} frames but holds {} complete frames; reading those", path, nframes, available);
    nframes = static_cast<long long>(available);
  }
  if (dstart > r.size() || available < static_cast<std::size_t>(nframes))
    r.fail(dstart, "the data section needs " + std::to_string(nframes) + " frames x " + std::to_string(frame_bytes) +
                       " bytes but the file has " + std::to_string(r.size() > dstart ? r.size() - dstart : 0) +
                       " bytes after byte " + std::to_string(dstart) + " (truncated C3D?)");
  const double nan = std::numeric_limits<double>::quiet_NaN();
  m.data.resize(nframes, 3 * npoints);
  const double s = std::abs(scale);
  for (long long f = 0; f < nframes; ++f) {
    const std::size_t fb = dstart + static_cast<std::size_t>(f) * frame_bytes;
    for (int p = 0; p < npoints; ++p) {
      const std::size_t pb = fb + static_cast<std::size_t>(p) * 4 * word;
      double x, y, z, res;
      if (word == 4) {
        x = r.f32(pb, "point data");
        y = r.f32(pb + 4, "point data");
        z = r.f32(pb + 8, "point data");
        res = r.f32(pb + 12, "point data");
      } else {
        x = r.i16(pb, "point data") * s;
        y = r.i16(pb + 2, "point data") * s;
        z = r.i16(pb + 4, "point data") * s;
        res = r.i16(pb + 6, "point data");
      }
      const bool ok = res >= 0 && std::isfinite(x) && std::isfinite(y) && std::isfinite(z);
      m.data(f, 3 * p) = ok ? x : nan;
      m.data(f, 3 * p + 1) = ok ? y : nan;
      m.data(f, 3 * p + 2) = ok ? z : nan;
    }
  }
  return m;
}

// ----------------------------------------------------------------------------------------- BVH
int BvhMotion::numJoints() const {
  int n = 0;
  for (const auto& j : joints) n += !j.end_site;
  return n;
}

std::vector<Eigen::Isometry3d> BvhMotion::globalTransforms(int frame) const {
  if (frame < 0 || frame >= numFrames())
    throw InvalidInput("[tbsp::BvhMotion::globalTransforms] frame " + std::to_string(frame) + " out of range [0, " +
                       std::to_string(numFrames()) + ")");
  std::vector<Eigen::Isometry3d> G(joints.size());
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const BvhJoint& j = joints[i];
    Eigen::Vector3d tr = j.offset;
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    for (std::size_t c = 0; c < j.channels.size(); ++c) {
      const double v = motion(frame, j.first_channel + static_cast<int>(c));
      switch (j.channels[c]) {
        case BvhJoint::Xposition: tr.x() += v; break;
        case BvhJoint::Yposition: tr.y() += v; break;
        case BvhJoint::Zposition: tr.z() += v; break;
        case BvhJoint::Xrotation: R = R * Eigen::AngleAxisd(v * M_PI / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix(); break;
        case BvhJoint::Yrotation: R = R * Eigen::AngleAxisd(v * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix(); break;
        case BvhJoint::Zrotation: R = R * Eigen::AngleAxisd(v * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix(); break;
      }
    }
    Eigen::Isometry3d L = Eigen::Isometry3d::Identity();
    L.linear() = R;
    L.translation() = tr;
    G[i] = j.parent >= 0 ? G[static_cast<std::size_t>(j.parent)] * L : L;
  }
  return G;
}

Eigen::MatrixX3d BvhMotion::jointPositions(int frame) const {
  const auto G = globalTransforms(frame);
  Eigen::MatrixX3d P(G.size(), 3);
  for (std::size_t i = 0; i < G.size(); ++i) P.row(static_cast<Eigen::Index>(i)) = G[i].translation().transpose();
  return P;
}

namespace {
void bvh_expect(detail::TextBuffer& tb, std::string_view want) {
  std::string_view t;
  if (!tb.token(t)) tb.fail("file ends where '" + std::string(want) + "' was expected (truncated BVH?)");
  if (t != want) tb.fail("expected '" + std::string(want) + "', found '" + std::string(t) + "'");
}

void bvh_joint(detail::TextBuffer& tb, BvhMotion& m, int parent, bool end_site, std::string name, int depth, int& nch) {
  if (depth > 1000) tb.fail("hierarchy nested deeper than 1000 levels");
  if (m.joints.size() > 100000) tb.fail("more than 100000 joints");
  BvhJoint j;
  j.name = std::move(name);
  j.parent = parent;
  j.end_site = end_site;
  j.first_channel = nch;
  bvh_expect(tb, "{");
  bvh_expect(tb, "OFFSET");
  for (int k = 0; k < 3; ++k) {
    j.offset(k) = tb.readDouble("OFFSET value of '" + j.name + "'");
    if (!std::isfinite(j.offset(k))) tb.fail("OFFSET of '" + j.name + "' is not finite");
  }
  const int me = static_cast<int>(m.joints.size());
  std::string_view t;
  if (!end_site) {
    bvh_expect(tb, "CHANNELS");
    const long long n = tb.readInt("channel count of '" + j.name + "'");
    if (n < 0 || n > 6) tb.fail("joint '" + j.name + "' has " + std::to_string(n) + " channels (0..6 allowed)");
    for (long long c = 0; c < n; ++c) {
      if (!tb.token(t)) tb.fail("file ends inside the CHANNELS of '" + j.name + "'");
      static const std::pair<const char*, BvhJoint::Channel> names[] = {
          {"Xposition", BvhJoint::Xposition}, {"Yposition", BvhJoint::Yposition}, {"Zposition", BvhJoint::Zposition},
          {"Xrotation", BvhJoint::Xrotation}, {"Yrotation", BvhJoint::Yrotation}, {"Zrotation", BvhJoint::Zrotation}};
      bool ok = false;
      for (const auto& [s, ch] : names)
        if (t == s) { j.channels.push_back(ch); ok = true; }
      if (!ok) tb.fail("unknown channel '" + std::string(t) + "' of joint '" + j.name + "' (X/Y/Z position/rotation)");
    }
    nch += static_cast<int>(n);
  }
  m.joints.push_back(j);
  while (true) {
    if (!tb.token(t)) tb.fail("file ends inside joint '" + m.joints[me].name + "' (missing '}')");
    if (t == "}") break;
    if (end_site) tb.fail("unexpected '" + std::string(t) + "' inside an End Site");
    if (t == "JOINT") {
      std::string_view nm;
      if (!tb.token(nm)) tb.fail("JOINT without a name");
      bvh_joint(tb, m, me, false, std::string(nm), depth + 1, nch);
    } else if (t == "End") {
      bvh_expect(tb, "Site");
      bvh_joint(tb, m, me, true, m.joints[me].name + "_End", depth + 1, nch);
    } else {
      tb.fail("expected JOINT, End Site or '}', found '" + std::string(t) + "'");
    }
  }
}
}  // namespace

BvhMotion read_bvh(const std::string& path) {
  auto tb = detail::TextBuffer::load(path);
  BvhMotion m;
  std::string_view t;
  if (!tb.token(t) || t != "HIERARCHY") tb.fail("not a BVH file: it must start with 'HIERARCHY'");
  int nch = 0;
  while (true) {
    if (!tb.token(t)) tb.fail("file ends before MOTION (truncated BVH?)");
    if (t == "MOTION") break;
    if (t != "ROOT") tb.fail("expected ROOT or MOTION, found '" + std::string(t) + "'");
    std::string_view nm;
    if (!tb.token(nm)) tb.fail("ROOT without a name");
    bvh_joint(tb, m, -1, false, std::string(nm), 0, nch);
  }
  if (m.joints.empty()) tb.fail("no ROOT joint before MOTION");
  bvh_expect(tb, "Frames:");
  const long long nframes = tb.readInt("frame count after 'Frames:'");
  if (nframes < 0 || nframes > 10000000) tb.fail("frame count " + std::to_string(nframes) + " is not plausible");
  bvh_expect(tb, "Frame");
  bvh_expect(tb, "Time:");
  m.frame_time = tb.readDouble("frame time after 'Frame Time:'");
  if (!(m.frame_time > 0) || !std::isfinite(m.frame_time)) tb.fail("frame time must be a positive number");
  // Every value needs at least 2 bytes ("0 "): reject absurd counts before allocating.
  if (static_cast<double>(nframes) * std::max(nch, 1) > static_cast<double>(tb.remaining()))
    tb.fail("'Frames: " + std::to_string(nframes) + "' x " + std::to_string(nch) + " channels cannot fit in the remaining " +
            std::to_string(tb.remaining()) + " bytes (truncated file or wrong frame count)");
  m.motion.resize(nframes, nch);
  for (long long f = 0; f < nframes; ++f)
    for (int c = 0; c < nch; ++c) {
      double v;
      if (!tb.token(t)) tb.fail("file ends in frame " + std::to_string(f + 1) + " of " + std::to_string(nframes) + " (truncated BVH?)");
      if (!detail::parse_double(t, v) || !std::isfinite(v))
        tb.fail("motion value '" + std::string(t) + "' (frame " + std::to_string(f + 1) + ", channel " + std::to_string(c + 1) + ") is not a finite number");
      m.motion(f, c) = v;
    }
  if (tb.token(t)) tb.fail("unexpected '" + std::string(t) + "' after the " + std::to_string(nframes) + " frames (wrong 'Frames:' count?)");
  return m;
}

void write_bvh(const std::string& path, const BvhMotion& m) {
  int nch = 0;
  for (const auto& j : m.joints) nch += static_cast<int>(j.channels.size());
  if (nch != m.numChannels())
    throw InvalidInput("[tbsp::write_bvh] joints declare " + std::to_string(nch) + " channels but motion has " + std::to_string(m.numChannels()));
  static const char* cname[] = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"};
  std::ostringstream os;
  os << std::setprecision(10) << "HIERARCHY\n";
  std::vector<std::vector<int>> children(m.joints.size());
  for (std::size_t i = 0; i < m.joints.size(); ++i)
    if (m.joints[i].parent >= 0) children[static_cast<std::size_t>(m.joints[i].parent)].push_back(static_cast<int>(i));
  std::function<void(int, int)> emit = [&](int i, int depth) {
    const BvhJoint& j = m.joints[static_cast<std::size_t>(i)];
    const std::string ind(static_cast<std::size_t>(2 * depth), ' ');
    if (j.end_site) os << ind << "End Site\n";
    else os << ind << (j.parent < 0 ? "ROOT " : "JOINT ") << j.name << "\n";
    os << ind << "{\n" << ind << "  OFFSET " << j.offset.x() << ' ' << j.offset.y() << ' ' << j.offset.z() << "\n";
    if (!j.end_site) {
      os << ind << "  CHANNELS " << j.channels.size();
      for (auto c : j.channels) os << ' ' << cname[c];
      os << "\n";
    }
    for (int c : children[static_cast<std::size_t>(i)]) emit(c, depth + 1);
    os << ind << "}\n";
  };
  for (std::size_t i = 0; i < m.joints.size(); ++i)
    if (m.joints[i].parent < 0) emit(static_cast<int>(i), 0);
  os << "MOTION\nFrames: " << m.numFrames() << "\nFrame Time: " << m.frame_time << "\n";
  for (int f = 0; f < m.numFrames(); ++f) {
    for (int c = 0; c < nch; ++c) os << (c ? " " : "") << m.motion(f, c);
    os << "\n";
  }
  write_text_file_atomic(path, os.str());
}

}  // namespace tbsp
