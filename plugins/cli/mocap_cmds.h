#pragma once
// `tbsp mocap`: inspect and convert motion-capture files (TRC, C3D markers; BVH skeletons).
#include <string>

#include <CLI/CLI.hpp>

namespace tbsp::cli {

struct MocapArgs {
  std::string input, out, json, units;
  bool end_sites = false;  // BVH -> positions: include End Site points
  bool quiet = false;
};
void add_mocap(CLI::App& app, MocapArgs& a, CLI::App*& sub);
int cmd_mocap(const MocapArgs& a);

}  // namespace tbsp::cli
