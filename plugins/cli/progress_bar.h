#pragma once
// Terminal progress bar for the CLI: a redrawn bar on a TTY, a few log lines otherwise.
#include <string>

#include "tbsp/core/progress.h"

namespace tbsp::cli {

class ProgressBar {
public:
  explicit ProgressBar(bool enabled);
  ~ProgressBar();
  ProgressCallback callback();
  void finish();

private:
  bool enabled_, tty_;
  int last_percent_ = -1;
  std::string last_stage_;
  bool drawn_ = false;
};

}  // namespace tbsp::cli
