#include "progress_bar.h"

#include <cstdio>
#include <unistd.h>

namespace tbsp::cli {

ProgressBar::ProgressBar(bool enabled) : enabled_(enabled), tty_(::isatty(2) != 0) {}
ProgressBar::~ProgressBar() { finish(); }

ProgressCallback ProgressBar::callback() {
  if (!enabled_) return {};
  return [this](double f, const std::string& stage) {
    const int pct = int(f * 100.0 + 0.5);
    if (pct == last_percent_ && stage == last_stage_) return true;
    if (tty_) {
      const int width = 30, fill = pct * width / 100;
      std::fprintf(stderr, "\r[%.*s%*s] %3d%% %-20s", fill, "##############################", width - fill, "", pct,
                   stage.c_str());
      std::fflush(stderr);
      drawn_ = true;
    }  // not a terminal (CI logs, pipes): stay quiet
    last_percent_ = pct;
    last_stage_ = stage;
    return true;
  };
}

void ProgressBar::finish() {
  if (drawn_) std::fprintf(stderr, "\n");
  drawn_ = false;
}

}  // namespace tbsp::cli
