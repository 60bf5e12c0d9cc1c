#include "studio_frames.h"

#include <filesystem>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

std::pair<int, int> parse_frames(const std::string& s, const Studio& st) {
  if (s.empty()) return {st.first_frame, st.last_frame};
  int a = 0, b = 0;
  char c = 0;
  std::istringstream is(s);
  if (!(is >> a)) throw InvalidInput("--frames '" + s + "': expected a or a:b (frame numbers)");
  b = a;
  if (is >> c) {
    if (c != ':' || !(is >> b)) throw InvalidInput("--frames '" + s + "': expected a or a:b (frame numbers)");
  }
  if (a > b || a < st.first_frame || b > st.last_frame)
    throw InvalidInput("--frames " + s + " is outside the studio's frames " + std::to_string(st.first_frame) + ".." + std::to_string(st.last_frame));
  return {a, b};
}

int for_each_frame(const Studio& st, int first, int last, bool silhouettes, bool quiet,
                   const std::function<void(const StudioFrame&, const ProgressCallback&, ProgressBar&)>& run) {
  StudioFrameStream::Options so;
  so.first = first;
  so.last = last;
  so.silhouettes = silhouettes;
  StudioFrameStream stream(st, so);
  ProgressBar bar(!quiet);
  const ProgressCallback cb = bar.callback();
  StudioFrame fr;
  const int total = last - first + 1;
  int done = 0;
  while (stream.next(fr)) {
    const int base = done;
    const ProgressCallback frame_cb = [&](double x, const std::string& stage) {
      return !cb || cb((base + x) / total, "frame " + std::to_string(fr.frame) + ": " + stage);
    };
    run(fr, frame_cb, bar);
    ++done;
  }
  return done;
}

void write_png(const std::string& path, const cv::Mat& m) {
  atomic_write_with(path, [&](const std::string& tmp) {
    const std::string t = tmp + ".png";
    if (!cv::imwrite(t, m)) return false;
    fs::rename(t, tmp);
    return true;
  });
}

}  // namespace tbsp::cli
