#pragma once
// `tbsp texture`: inverse texture mapping (thesis ch. 4) and pattern draping (§4.4).
#include <string>

#include <CLI/CLI.hpp>

namespace tbsp::cli {

struct TextureArgs {
  std::string mesh, image, constraints, out, mask, surface, report, render;
  double omega = 10.0, sigma = 1.0, offset = 0.0, epsilon = 0.01;
  long max_solve_nodes = 400000, max_geodesic_nodes = 70000;
  bool plane = false, no_mismatch = false, quiet = false;
};
void add_texture(CLI::App& app, TextureArgs& a, CLI::App*& sub);
int cmd_texture(const TextureArgs& a);

}  // namespace tbsp::cli
