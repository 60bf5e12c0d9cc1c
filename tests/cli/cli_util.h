#pragma once
// Runs the `tbsp` executable for the CLI tests: exit code and stderr.
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace tbsp::test {

struct CliResult {
  int code;
  std::string out, err;
};

/// Runs `tbsp ARGS` (or the program `exe`); stdout and stderr are captured through files in `dir`.
inline CliResult run_cli(const std::string& args, const std::filesystem::path& dir, const std::string& exe = TBSP_CLI) {
  const std::string outf = (dir / "stdout.txt").string(), errf = (dir / "stderr.txt").string();
  const int rc = std::system((exe + " " + args + " >" + outf + " 2>" + errf).c_str());
  auto slurp = [](const std::string& f) {
    std::ifstream in(f);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  };
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, slurp(outf), slurp(errf)};
}

}  // namespace tbsp::test
