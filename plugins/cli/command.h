#pragma once
// The `tbsp` command table: every sub-command registers itself (options on the CLI11 app, and
// what to run when it is chosen); main() parses, runs the chosen one and maps exceptions to exit
// codes (0 ok, 2 invalid input, 3 numerical failure, 130 cancelled, 1 anything else).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "tbsp/core/error.h"

namespace tbsp::cli {

struct Command {
  CLI::App* app = nullptr;     ///< the sub-command, as registered
  std::function<int()> run;    ///< runs it with the parsed options; returns the exit code
};
using CommandTable = std::vector<Command>;

/// `count` indices spread evenly over 0..n-1 (first and last included), sorted, no duplicates:
/// the frames of a contact sheet.
inline std::vector<int> evenly_spread(int count, int n) {
  std::vector<int> f;
  for (int k = 0; k < count && n > 0; ++k) f.push_back(count == 1 ? 0 : static_cast<int>((static_cast<long>(k) * (n - 1) * 2 + (count - 1)) / (2L * (count - 1))));
  f.erase(std::unique(f.begin(), f.end()), f.end());
  return f;
}

/// Creates the output folder `out` (and its parents). \throws FileError when it cannot.
inline void make_out_dir(const std::string& out) {
  std::error_code ec;
  std::filesystem::create_directories(out, ec);
  if (ec || !std::filesystem::is_directory(out)) throw FileError("'" + out + "': cannot create the output folder (" + ec.message() + ")");
}

/// The file's extension in lower case, with the dot (".c3d"); "" when it has none.
inline std::string lower_ext(const std::string& path) {
  std::string e = std::filesystem::path(path).extension().string();
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

/// Registers a command written as `add_X(app, args, sub)` + `cmd_X(args)`: the options live
/// in a shared Args object that the run function receives.
template <class Args, class Add, class Run>
void register_command(CLI::App& app, CommandTable& table, Add add, Run run) {
  auto args = std::make_shared<Args>();
  CLI::App* sub = nullptr;
  add(app, *args, sub);
  table.push_back({sub, [args, run] { return run(*args); }});
}

void add_deform_commands(CLI::App& app, CommandTable& table);   // deform
void add_fit_commands(CLI::App& app, CommandTable& table);      // fit, synth-scan
void add_mesh_commands(CLI::App& app, CommandTable& table);     // validate, convert, render, generate
void add_demo_commands(CLI::App& app, CommandTable& table);     // demo
void add_capture_commands(CLI::App& app, CommandTable& table);  // synth-studio, replay
void add_tet_commands(CLI::App& app, CommandTable& table);      // tetdeform
void add_texture_commands(CLI::App& app, CommandTable& table);  // texture
void add_mocap_commands(CLI::App& app, CommandTable& table);    // mocap
void add_stereo_commands(CLI::App& app, CommandTable& table);   // stereo, refine-stereo, refine-silhouette
void add_animate_commands(CLI::App& app, CommandTable& table);  // animate
void add_perf_capture_commands(CLI::App& app, CommandTable& table);  // capture
void add_pipeline_commands(CLI::App& app, CommandTable& table);  // plugins, run
void add_cloth_commands(CLI::App& app, CommandTable& table);     // cloth synth|segment|build|animate

}  // namespace tbsp::cli
