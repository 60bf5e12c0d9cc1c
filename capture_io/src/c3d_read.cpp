// C3D marker trajectories: read_c3d (write_c3d: c3d_write.cpp).
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

}  // namespace tbsp
