#pragma once
/// \file logging.h
/// \brief tbsp's logger (spdlog). All library messages go through tbsp::logger(), named "tbsp".
/// The application owns verbosity: `tbsp::logger()->set_level(spdlog::level::debug)`.

#include <memory>
#include <spdlog/spdlog.h>

namespace tbsp {

/// The shared logger (created on first use, writes to stderr). Thread-safe.
std::shared_ptr<spdlog::logger> logger();

}  // namespace tbsp
