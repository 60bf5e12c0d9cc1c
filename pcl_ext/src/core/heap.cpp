#include "tbsp/core/heap.h"

#include <climits>
#include <cstdlib>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace tbsp {

bool keep_freed_memory(std::size_t mmap_bytes, std::size_t trim_bytes) {
#if defined(__GLIBC__)
  if (std::getenv("TBSP_DEFAULT_MALLOC")) return false;
  if (mmap_bytes > std::size_t(INT_MAX) || trim_bytes > std::size_t(INT_MAX)) return false;
  const bool mmap_ok = mallopt(M_MMAP_THRESHOLD, int(mmap_bytes)) == 1;
  const bool trim_ok = mallopt(M_TRIM_THRESHOLD, int(trim_bytes)) == 1;
  return mmap_ok && trim_ok;
#else
  (void)mmap_bytes;
  (void)trim_bytes;
  return false;
#endif
}

}  // namespace tbsp
