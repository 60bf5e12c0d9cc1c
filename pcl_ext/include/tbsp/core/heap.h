#pragma once
/// \file heap.h
/// \brief Freed memory kept for re-use in per-frame loops (glibc).
///
/// glibc's malloc serves allocations above its mmap threshold (128 KiB at start, raised to the
/// size of the largest such block freed so far, at most 32 MiB) with fresh pages from the
/// kernel, and gives freed memory above its trim threshold back. A per-frame loop that
/// allocates the same large blocks every frame (OpenCV's SIFT pyramids, 1-8 MiB per view)
/// then page-faults on all of them every frame, and whether it does depends on whether some
/// other large block happened to be freed first (docs/performance_capture.md, "Speed").
/// The `tbsp` CLI and the capture benchmark call keep_freed_memory() at start; library users
/// can do the same, or set `GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=134217728`.
/// It changes no result, only where memory comes from; the cost is up to `trim_bytes` of freed
/// memory the process keeps instead of returning it.

#include <cstddef>

namespace tbsp {

/// \brief Sets glibc's mmap threshold to `mmap_bytes` (blocks up to that size come from the
/// heap and are re-used after free; glibc's maximum is 32 MiB on 64-bit) and its trim threshold
/// to `trim_bytes` (the heap keeps up to that much freed memory). Does nothing when
/// `TBSP_DEFAULT_MALLOC` is set (any value), or without glibc. Returns whether both were set.
/// Call it at the start of main(), before threads allocate.
bool keep_freed_memory(std::size_t mmap_bytes = std::size_t(32) << 20, std::size_t trim_bytes = std::size_t(128) << 20);

}  // namespace tbsp
