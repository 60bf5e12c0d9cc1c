#pragma once
// Small helpers shared by the bench CLIs (bench_stereo, bench_capture_perf, bench_fit).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "tbsp/core/heap.h"
#include "tbsp/core/huge_pages.h"

namespace tbsp::bench {

using Clock = std::chrono::steady_clock;
inline double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }
/// Peak resident memory of this process (VmHWM), MB.
inline double peak_rss_mb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  return 0;
}
/// The heap as the tbsp CLI sets it up: huge pages (re-executes the program once,
/// tbsp/core/huge_pages.h) and freed memory kept for re-use (tbsp/core/heap.h); prints both.
/// Compare with TBSP_NO_HUGE_PAGES=1 / TBSP_DEFAULT_MALLOC=1. Call first in main().
inline void heap_as_the_cli(char** argv) {
  reexec_with_huge_pages(argv);
  const bool kept = keep_freed_memory();
  std::printf("heap: huge pages %s, freed memory kept for re-use %s\n",
              std::getenv("GLIBC_TUNABLES") ? std::getenv("GLIBC_TUNABLES") : "(not asked for)",
              kept ? "yes" : "no (TBSP_DEFAULT_MALLOC)");
}
inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace tbsp::bench
