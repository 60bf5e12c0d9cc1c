#pragma once
// `tbsp synth-studio` and `tbsp replay` (capture_io front ends).
#include <string>

#include <CLI/CLI.hpp>

#include "tbsp/plugins/synth_studio.h"

namespace tbsp::cli {

struct SynthStudioArgs {
  std::string out;
  synth::StudioOptions o;
  bool quiet = false;
};
void add_synth_studio(CLI::App& app, SynthStudioArgs& a, CLI::App*& sub);
int cmd_synth_studio(const SynthStudioArgs& a);

struct ReplayArgs {
  std::string input, out, format = "pcd";
  int first = -1, last = -1;
  std::string intrinsics;  // "fx,fy,cx,cy" for depth-image folders
  double depth_scale = 0.001;
  bool check_only = false;
};
void add_replay(CLI::App& app, ReplayArgs& a, CLI::App*& sub);
int cmd_replay(const ReplayArgs& a);

}  // namespace tbsp::cli
