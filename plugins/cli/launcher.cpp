// The `tbsp` command: a small program (libc and libstdc++ only) that starts the CLI proper,
// `tbsp-cli`, with transparent huge pages asked for in its environment (tbsp/core/huge_pages.h).
//
// Why a launcher: glibc reads its malloc tunables once, when a program starts, so the CLI used
// to re-execute itself to get huge pages, and loaded its ~300 shared libraries (PCL, VTK, OpenCV,
// CHOLMOD, ...) twice: `tbsp --help` took 1.3 s, 0.7 s of it the second load. Setting the
// tunable here, before anything large is loaded, costs one exec of this small program instead.
//
// Where tbsp-cli is looked for, in this order: next to this program (the build tree), then in
// the directory the install puts it in, relative to this program's directory (TBSP_CLI_RELDIR,
// e.g. ../libexec). The arguments, the environment (plus the tunable) and argv[0] are passed on
// unchanged, so messages and usage lines still say `tbsp`.

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include <climits>
#include <unistd.h>

#include "tbsp/core/huge_pages.h"

#ifndef TBSP_CLI_RELDIR
#define TBSP_CLI_RELDIR "../libexec"
#endif

namespace {

/// The directory of this program: /proc/self/exe (symbolic links resolved), else argv[0]'s
/// directory when it has one, else "" (not found; the search below then fails clearly).
std::string own_directory(const char* argv0) {
  char buf[PATH_MAX];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof buf - 1);
  std::string path;
  if (n > 0) {
    buf[n] = '\0';
    path = buf;
  } else if (argv0 && std::strchr(argv0, '/')) {
    path = argv0;
  }
  const std::size_t slash = path.rfind('/');
  if (slash == std::string::npos) return {};
  return slash == 0 ? std::string("/") : path.substr(0, slash);
}

}  // namespace

int main(int argc, char** argv) {
  (void)argc;
  const std::string dir = own_directory(argv[0]);
  const std::string candidates[] = {dir + "/tbsp-cli", dir + "/" TBSP_CLI_RELDIR "/tbsp-cli"};
  tbsp::request_huge_pages();
  int last_error = ENOENT;
  for (const std::string& path : candidates) {
    if (dir.empty()) break;
    if (access(path.c_str(), X_OK) != 0) {
      if (errno != ENOENT) last_error = errno;  // there but not executable (EACCES): say so below
      continue;
    }
    execv(path.c_str(), argv);
    last_error = errno;  // found but could not be executed: report it below
  }
  std::fprintf(stderr,
               "tbsp: cannot start the CLI program tbsp-cli (looked for %s and %s: %s).\n"
               "Fix: reinstall tbsp (cmake --install keeps bin/tbsp and %s/tbsp-cli together), or run tbsp-cli directly.\n",
               candidates[0].c_str(), candidates[1].c_str(), std::strerror(last_error), TBSP_CLI_RELDIR);
  return 127;
}
