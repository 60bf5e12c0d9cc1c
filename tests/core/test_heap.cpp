// tbsp::keep_freed_memory (tbsp/core/heap.h): after it, a block of a few MiB comes from the
// heap (re-used after free) instead of a fresh mapping; TBSP_DEFAULT_MALLOC turns it off.
// tbsp::request_huge_pages (tbsp/core/huge_pages.h): the tunable the `tbsp` launcher sets.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "tbsp/core/heap.h"
#include "tbsp/core/huge_pages.h"

#if defined(__GLIBC__)
TEST(Heap, KeepFreedMemoryServesLargeBlocksFromTheHeap) {
  setenv("TBSP_DEFAULT_MALLOC", "1", 1);
  EXPECT_FALSE(tbsp::keep_freed_memory());  // switched off: nothing set
  unsetenv("TBSP_DEFAULT_MALLOC");
  EXPECT_FALSE(tbsp::keep_freed_memory(std::size_t(1) << 40));  // beyond mallopt's int: refused
  ASSERT_TRUE(tbsp::keep_freed_memory());
  const std::size_t bytes = std::size_t(8) << 20;  // a SIFT pyramid level of a 1004² view
  const int mapped = mallinfo2().hblks;
  for (int round = 0; round < 3; ++round) {
    char* p = static_cast<char*>(std::malloc(bytes));
    ASSERT_NE(p, nullptr);
    std::memset(p, round, bytes);
    EXPECT_EQ(mallinfo2().hblks, mapped) << "round " << round << ": the block was mapped, not taken from the heap";
    std::free(p);
  }
}
#endif

#if defined(__linux__) && defined(__GLIBC__)
TEST(HugePages, RequestAddsTheTunableOnlyWhenItIsNeeded) {
  const char* saved = std::getenv("GLIBC_TUNABLES");
  const std::string before = saved ? saved : "";
  const bool had = saved != nullptr;
  auto tunables = [] {
    const char* v = std::getenv("GLIBC_TUNABLES");
    return std::string(v ? v : "<unset>");
  };
  setenv("TBSP_NO_HUGE_PAGES", "1", 1);
  setenv("GLIBC_TUNABLES", "glibc.malloc.check=0", 1);
  EXPECT_FALSE(tbsp::request_huge_pages());  // switched off
  EXPECT_EQ(tunables(), "glibc.malloc.check=0");
  unsetenv("TBSP_NO_HUGE_PAGES");
  setenv("GLIBC_TUNABLES", "glibc.malloc.hugetlb=0", 1);
  EXPECT_FALSE(tbsp::request_huge_pages());  // the user's own choice is kept
  EXPECT_EQ(tunables(), "glibc.malloc.hugetlb=0");
  setenv("GLIBC_TUNABLES", "glibc.malloc.check=0", 1);
  std::string mode;
  std::getline(std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled"), mode);
  if (mode.find("[madvise]") != std::string::npos) {  // this kernel needs asking: appended
    EXPECT_TRUE(tbsp::request_huge_pages());
    EXPECT_EQ(tunables(), "glibc.malloc.check=0:glibc.malloc.hugetlb=1");
  } else {  // always / never / no THP: nothing to ask for
    EXPECT_FALSE(tbsp::request_huge_pages());
    EXPECT_EQ(tunables(), "glibc.malloc.check=0");
  }
  if (had) setenv("GLIBC_TUNABLES", before.c_str(), 1);
  else unsetenv("GLIBC_TUNABLES");
}
#endif
