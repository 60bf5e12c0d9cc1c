#pragma once
/// \file progress.h
/// \brief Progress reporting and cancellation for long operations.
///
/// A ProgressCallback receives the fraction done in [0,1] and a short stage name. It returns
/// true to continue and false to cancel; the operation then throws tbsp::Cancelled and
/// leaves its outputs untouched.

#include <functional>
#include <string>

#include "tbsp/core/error.h"

namespace tbsp {

using ProgressCallback = std::function<bool(double fraction, const std::string& stage)>;

/// Calls `cb` if set and throws Cancelled when it asks to stop.
inline void report_progress(const ProgressCallback& cb, double fraction, const std::string& stage) {
  if (cb && !cb(fraction, stage)) throw Cancelled("cancelled during '" + stage + "'");
}

}  // namespace tbsp
