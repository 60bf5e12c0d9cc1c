// tbsp::keep_freed_memory (tbsp/core/heap.h): after it, a block of a few MiB comes from the
// heap (re-used after free) instead of a fresh mapping; TBSP_DEFAULT_MALLOC turns it off.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "tbsp/core/heap.h"

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
