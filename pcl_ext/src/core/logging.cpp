#include "tbsp/core/logging.h"

#include <mutex>
#include <spdlog/sinks/stdout_color_sinks.h>

namespace tbsp {

std::shared_ptr<spdlog::logger> logger() {
  static std::once_flag once;
  static std::shared_ptr<spdlog::logger> log;
  std::call_once(once, [] {
    log = spdlog::get("tbsp");
    if (!log) log = spdlog::stderr_color_mt("tbsp");
    log->set_pattern("[%H:%M:%S.%e] [%n] [%^%l%$] %v");
  });
  return log;
}

}  // namespace tbsp
