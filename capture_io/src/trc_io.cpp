// TRC marker trajectories (OpenSim / Motion Analysis): read_trc, write_trc.
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

}  // namespace tbsp
