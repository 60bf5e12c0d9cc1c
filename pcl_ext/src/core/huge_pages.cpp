#include "tbsp/core/huge_pages.h"

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

#if defined(__linux__)
#include <unistd.h>
#endif

namespace tbsp {

bool request_huge_pages() {
#if defined(__linux__) && defined(__GLIBC__)
  if (std::getenv("TBSP_NO_HUGE_PAGES")) return false;
  const char* cur = std::getenv("GLIBC_TUNABLES");
  const std::string tunables = cur ? cur : "";
  if (tunables.find("glibc.malloc.hugetlb") != std::string::npos) return false;  // set (by us or the user)
  std::ifstream thp("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string mode;
  std::getline(thp, mode);
  // only "madvise" needs asking: "always" gives huge pages anyway, "never" none at all
  if (!thp || mode.find("[madvise]") == std::string::npos) return false;
  const std::string value = tunables.empty() ? "glibc.malloc.hugetlb=1" : tunables + ":glibc.malloc.hugetlb=1";
  return setenv("GLIBC_TUNABLES", value.c_str(), 1) == 0;
#else
  return false;
#endif
}

void reexec_with_huge_pages(char** argv) {
#if defined(__linux__) && defined(__GLIBC__)
  const char* cur = std::getenv("GLIBC_TUNABLES");
  const std::string before = cur ? cur : "";
  if (!request_huge_pages()) return;
  execv("/proc/self/exe", argv);
  // execv failed (no /proc, a sandbox): carry on with normal pages, without the variable so
  // that child processes see what the user set
  if (cur) setenv("GLIBC_TUNABLES", before.c_str(), 1);
  else unsetenv("GLIBC_TUNABLES");
#else
  (void)argv;
#endif
}

}  // namespace tbsp
