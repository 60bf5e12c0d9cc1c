// Motion capture: what the formats share (trc_io.cpp, c3d_read.cpp, c3d_write.cpp and bvh_io.cpp hold the readers and writers).
#include "tbsp/io/mocap_io.h"

#include <cctype>
#include <cmath>
#include <filesystem>
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

MarkerTrajectories read_markers(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (auto& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".c3d") return read_c3d(path);
  if (ext == ".trc") return read_trc(path);
  throw InvalidInput(path + ": expected a .c3d or .trc file of marker trajectories");
}

double marker_units_to_metres(const std::string& units) {
  if (units == "mm") return 1e-3;
  if (units == "cm") return 1e-2;
  if (units == "m") return 1.0;
  throw InvalidInput("units '" + units + "' cannot be converted to metres (known: mm, cm, m)");
}

}  // namespace tbsp
