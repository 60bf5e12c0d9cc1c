#pragma once
// Small helpers shared by the bench CLIs (bench_stereo, bench_capture_perf).
#include <algorithm>
#include <chrono>
#include <fstream>
#include <string>
#include <vector>

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
inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace tbsp::bench
