// tbsp — command-line front end of the tbsp plugin suite. Each command group registers itself
// in the command table (command.h); this file parses, runs the chosen command and turns
// exceptions into exit codes.
#include <CLI/CLI.hpp>

#include <iostream>

#include "command.h"
#include "tbsp/core/error.h"
#include "tbsp/core/heap.h"
#include "tbsp/core/huge_pages.h"
#include "tbsp/core/logging.h"

int main(int argc, char** argv) {
  tbsp::reexec_with_huge_pages(argv);  // before any thread starts (huge_pages.h)
  tbsp::keep_freed_memory();           // per-frame loops re-use their large blocks (heap.h)
  CLI::App app{"tbsp - template-based shape processing for PCL pipelines"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "tbsp 0.1.0");
  int verbose = 0;
  app.add_flag("-v,--verbose", verbose, "debug logging; -vv: trace (per-iteration timings of factorizations and solves; the extra diagnostics slow a fit down)");
  tbsp::cli::CommandTable table;
  tbsp::cli::add_deform_commands(app, table);
  tbsp::cli::add_fit_commands(app, table);
  tbsp::cli::add_mesh_commands(app, table);
  tbsp::cli::add_capture_commands(app, table);
  tbsp::cli::add_tet_commands(app, table);
  tbsp::cli::add_texture_commands(app, table);
  tbsp::cli::add_mocap_commands(app, table);
  tbsp::cli::add_stereo_commands(app, table);
  tbsp::cli::add_animate_commands(app, table);
  tbsp::cli::add_perf_capture_commands(app, table);
  tbsp::cli::add_pipeline_commands(app, table);
  tbsp::cli::add_cloth_commands(app, table);
  tbsp::cli::add_demo_commands(app, table);

  CLI11_PARSE(app, argc, argv);
  tbsp::logger()->set_level(verbose >= 2 ? spdlog::level::trace : verbose == 1 ? spdlog::level::debug : spdlog::level::warn);
  const std::string sub = app.get_subcommands().front()->get_name();
  try {
    for (const auto& c : table)
      if (c.app->parsed()) return c.run();
  } catch (const tbsp::Cancelled& e) {
    std::cerr << "tbsp " << sub << ": cancelled: " << e.what() << "\n";
    return 130;
  } catch (const tbsp::InvalidInput& e) {
    std::cerr << "tbsp " << sub << ": error: " << e.what() << "\n";
    return 2;
  } catch (const tbsp::NumericalFailure& e) {
    std::cerr << "tbsp " << sub << ": numerical failure: " << e.what() << "\n";
    return 3;
  } catch (const std::exception& e) {
    std::cerr << "tbsp " << sub << ": error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
