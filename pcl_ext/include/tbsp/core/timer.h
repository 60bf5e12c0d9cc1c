#pragma once
/// \file timer.h
/// \brief The one wall clock of tbsp's reports: every `t_*` / `timings_s` figure is
/// `seconds_since(start)` with start = `Clock::now()` (steady, monotonic; seconds as double).

#include <chrono>

namespace tbsp {

using Clock = std::chrono::steady_clock;

/// Seconds elapsed since `t0` (steady clock).
inline double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace tbsp
