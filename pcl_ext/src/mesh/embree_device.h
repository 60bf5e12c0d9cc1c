#pragma once
// Internal: the one Embree device of the process (creating one costs milliseconds; builds and
// queries on it are thread-safe). Created on first use; NumericalFailure if Embree cannot.
#include <embree3/rtcore.h>

namespace tbsp {
namespace detail {
RTCDevice embree_device();
}  // namespace detail
}  // namespace tbsp
