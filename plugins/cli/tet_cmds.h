#pragma once
// `tbsp tetdeform`: tetrahedralize, deform with TetDeformer (ch. 7), transfer to the input (§7.3).
#include <string>

#include <CLI/CLI.hpp>

namespace tbsp::cli {

struct TetDeformArgs {
  std::string mesh, handles, out, rigid, stiffness, report, save_tets;
  long tets = 5000;
  int iterations = 0;  // 0: from the handles file, else 50
  bool no_interpolation = false, quiet = false;
};
void add_tetdeform(CLI::App& app, TetDeformArgs& a, CLI::App*& sub);
int cmd_tetdeform(const TetDeformArgs& a);

}  // namespace tbsp::cli
