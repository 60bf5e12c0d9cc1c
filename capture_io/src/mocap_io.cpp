// Motion capture: what the formats share (trc_io.cpp, c3d_read.cpp, c3d_write.cpp and bvh_io.cpp hold the readers and writers).
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

}  // namespace tbsp
