// tbsp — command-line front end of the tbsp plugin suite. Each command group registers itself
// in the command table (command.h); this file parses, runs the chosen command and turns
// exceptions into exit codes.
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdlib>
#include <iostream>
#include <string>

#include "command.h"
#include "tbsp/core/error.h"
#include "tbsp/core/heap.h"
#include "tbsp/core/huge_pages.h"
#include "tbsp/core/logging.h"

namespace {

// CLI11's number validators (PositiveNumber, NonNegativeNumber, Range) compare with < and >, so
// "nan" passes every one of them; "inf" passes some. No tbsp option means anything with a
// non-finite number: the first such value of a parsed (sub)command's FLOAT option, or "".
std::string non_finite_option(const CLI::App* app) {
  for (const CLI::Option* o : app->get_options()) {
    if (o->count() == 0 || o->get_type_name().rfind("FLOAT", 0) != 0) continue;
    for (const std::string& v : o->results()) {
      char* end = nullptr;
      const double x = std::strtod(v.c_str(), &end);
      if (end != v.c_str() && !std::isfinite(x)) return o->get_name() + " " + v;
    }
  }
  for (const CLI::App* sub : app->get_subcommands()) {
    const std::string bad = non_finite_option(sub);
    if (!bad.empty()) return bad;
  }
  return "";
}

}  // namespace

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
  if (const std::string bad = non_finite_option(&app); !bad.empty()) {
    std::cerr << "tbsp " << sub << ": error: " << bad << " is not a finite number; give a finite value (see --help for its range)\n";
    return 2;
  }
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
