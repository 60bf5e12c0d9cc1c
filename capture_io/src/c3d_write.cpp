// C3D writer (Intel processor type, float point data): the inverse of read_c3d, so that marker
// trajectories convert TRC <-> C3D (`tbsp mocap`). Layout (c3d.org, "The C3D File Format User
// Guide"): block 1 header, blocks 2.. parameter section (groups POINT and ANALOG), then the data
// section, all in 512-byte blocks.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mocap_io.h"

namespace tbsp {

namespace {

class Bytes {
public:
  void u8(int v) { b_.push_back(static_cast<char>(static_cast<std::uint8_t>(v))); }
  void i8(int v) { b_.push_back(static_cast<char>(static_cast<std::int8_t>(v))); }
  void i16(int v) { raw<std::int16_t>(static_cast<std::int16_t>(v)); }
  void u16(int v) { raw<std::uint16_t>(static_cast<std::uint16_t>(v)); }
  void f32(double v) { raw<float>(static_cast<float>(v)); }
  void str(const std::string& s) { b_.append(s); }
  void pad_to_block() { b_.resize((b_.size() + 511) / 512 * 512, '\0'); }
  std::size_t size() const { return b_.size(); }
  std::string& data() { return b_; }
  void put_u16(std::size_t at, int v) {
    const auto x = static_cast<std::uint16_t>(v);
    std::memcpy(&b_[at], &x, 2);
  }
  void put_i16(std::size_t at, int v) {
    const auto x = static_cast<std::int16_t>(v);
    std::memcpy(&b_[at], &x, 2);
  }

private:
  template <class T>
  void raw(T v) {
    char c[sizeof(T)];
    std::memcpy(c, &v, sizeof(T));  // x86-64 is little-endian, as the Intel C3D type
    b_.append(c, sizeof(T));
  }
  std::string b_;
};

// Parameter section records. Each record's "next" field holds the byte distance from the field
// to the next record (0 on the last one); it is patched once the next record starts.
class ParameterWriter {
public:
  explicit ParameterWriter(Bytes& b) : b_(b) {}
  void group(int id, const std::string& name, const std::string& description) {
    begin(name, -id);
    b_.u8(int(description.size()));
    b_.str(description);
  }
  // returns the offset of the value (for patching)
  std::size_t param_i16(int group, const std::string& name, int v) {
    begin(name, group);
    b_.i8(2);
    b_.u8(0);
    const std::size_t at = b_.size();
    b_.i16(v);
    b_.u8(0);
    return at;
  }
  void param_f32(int group, const std::string& name, double v) {
    begin(name, group);
    b_.i8(4);
    b_.u8(0);
    b_.f32(v);
    b_.u8(0);
  }
  // char array: dims [len, n] (n = 1 for a single string: dims [len])
  void param_strings(int group, const std::string& name, const std::vector<std::string>& s, bool single) {
    std::size_t len = 1;
    for (const auto& x : s) len = std::max(len, x.size());
    begin(name, group);
    b_.i8(-1);
    if (single) {
      b_.u8(1);
      b_.u8(int(len));
    } else {
      b_.u8(2);
      b_.u8(int(len));
      b_.u8(int(s.size()));
    }
    for (const auto& x : s) b_.str(x + std::string(len - x.size(), ' '));
    b_.u8(0);
  }
  void finish() {
    if (last_next_ != std::string::npos) b_.put_i16(last_next_, 0);
  }

private:
  void begin(const std::string& name, int id) {
    if (last_next_ != std::string::npos) b_.put_i16(last_next_, int(b_.size() - last_next_));
    b_.i8(int(name.size()));
    b_.i8(id);
    b_.str(name);
    last_next_ = b_.size();
    b_.i16(0);
  }
  Bytes& b_;
  std::size_t last_next_ = std::string::npos;
};

}  // namespace

void write_c3d(const std::string& path, const MarkerTrajectories& m) {
  const std::string who = "[tbsp::write_c3d] " + path + ": ";
  const int n = m.numMarkers(), frames = m.numFrames();
  if (m.data.cols() != 3 * n)
    throw InvalidInput(who + "data has " + std::to_string(m.data.cols()) + " columns for " + std::to_string(n) +
                       " markers (need 3 per marker)");
  if (n < 1 || n > 65535) throw InvalidInput(who + std::to_string(n) + " markers; C3D holds 1 to 65535");
  if (frames < 1) throw InvalidInput(who + "no frames to write");
  if (!(m.frame_rate > 0) || !std::isfinite(m.frame_rate)) throw InvalidInput(who + "frame_rate must be positive");
  const int first = std::max(1, m.first_frame);
  if (static_cast<long long>(first) + frames - 1 > 65535)
    throw InvalidInput(who + "frames " + std::to_string(first) + ".." + std::to_string(first + frames - 1) +
                       " do not fit the 16-bit frame numbers of the C3D header (at most 65535); split the sequence");
  for (const auto& s : m.names)
    if (s.size() > 255) throw InvalidInput(who + "marker name '" + s.substr(0, 20) + "...' is longer than 255 characters");
  for (Eigen::Index i = 0; i < m.data.size(); ++i) {
    const double v = m.data.data()[i];
    if (std::isfinite(v) && std::abs(v) > 3e38) throw InvalidInput(who + "a coordinate exceeds the float range of C3D");
  }

  // ---- parameter section (block 2 on); its size decides where the data start
  Bytes par;
  par.u8(1);     // first parameter block
  par.u8(0x50);  // key
  par.u8(0);     // number of parameter blocks: patched below
  par.u8(84);    // processor type: Intel
  ParameterWriter pw(par);
  pw.group(1, "POINT", "3-D point parameters");
  pw.param_i16(1, "USED", n);
  pw.param_f32(1, "SCALE", -1.0);
  pw.param_f32(1, "RATE", m.frame_rate);
  const std::size_t data_start_at = pw.param_i16(1, "DATA_START", 0);  // patched below
  pw.param_i16(1, "FRAMES", frames);
  pw.param_strings(1, "UNITS", {m.units.empty() ? "m" : m.units}, true);
  for (int k = 0, part = 1; k < n; k += 255, ++part) {
    const std::vector<std::string> chunk(m.names.begin() + k, m.names.begin() + std::min(n, k + 255));
    pw.param_strings(1, part == 1 ? "LABELS" : "LABELS" + std::to_string(part), chunk, false);
  }
  pw.group(2, "ANALOG", "analog data parameters");
  pw.param_i16(2, "USED", 0);
  pw.param_f32(2, "RATE", m.frame_rate);
  pw.finish();
  par.pad_to_block();
  const int param_blocks = int(par.size() / 512);
  if (param_blocks > 255) throw InvalidInput(who + "too many markers for the C3D parameter section");
  const int data_block = 2 + param_blocks;
  if (data_block > 32767) throw InvalidInput(who + "parameter section too large");
  par.data()[2] = static_cast<char>(param_blocks);
  par.put_i16(data_start_at, data_block);

  // ---- header (block 1)
  Bytes head;
  head.u8(2);     // parameter section starts at block 2
  head.u8(0x50);  // key
  head.u16(n);
  head.u16(0);    // analog measurements per frame
  head.u16(first);
  head.u16(first + frames - 1);
  head.u16(0);    // maximum interpolation gap
  head.f32(-1.0);  // scale < 0: float data
  head.u16(data_block);
  head.u16(0);    // analog samples per frame
  head.f32(m.frame_rate);
  head.pad_to_block();

  // ---- data: x y z residual per marker and frame; a gap has residual -1 and zeros
  Bytes data;
  for (int f = 0; f < frames; ++f)
    for (int k = 0; k < n; ++k) {
      if (m.valid(f, k)) {
        for (int d = 0; d < 3; ++d) data.f32(m.data(f, 3 * k + d));
        data.f32(0.0);
      } else {
        for (int d = 0; d < 3; ++d) data.f32(0.0);
        data.f32(-1.0);
      }
    }
  data.pad_to_block();
  AtomicFile out(path, /*binary=*/true);
  out.stream() << head.data() << par.data() << data.data();
  out.commit();
}

}  // namespace tbsp
