// Internal: what the PBD kernels (pbd_bend_kernel.cpp, pbd_contact_kernel.cpp,
// pbd_stretch_kernel.cpp) share: four-lane double vectors and their loads (GCC/Clang vector extensions) and the
// attribute that builds each kernel twice, for AVX2 and for the baseline, picked at load time.
// The kernels are compiled with -ffp-contract=off (pcl_ext/CMakeLists.txt), so both builds
// round every lane exactly as the scalar code does. -DTBSP_NO_KERNEL_CLONES builds the baseline
// only (to check that it gives the same bits).
#pragma once

#include <cstdint>
#include <cstring>

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && !defined(TBSP_NO_KERNEL_CLONES)
#define TBSP_PBD_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#define TBSP_PBD_INLINE __attribute__((always_inline)) inline
#else
#define TBSP_PBD_CLONES
#define TBSP_PBD_INLINE inline
#endif

namespace tbsp {
namespace detail {
namespace simd {

typedef double v4 __attribute__((vector_size(32)));
typedef std::int64_t m4 __attribute__((vector_size(32)));  ///< lane masks: all bits set or none

TBSP_PBD_INLINE v4 splat(double x) { return v4{x, x, x, x}; }
/// Four consecutive doubles (any alignment).
TBSP_PBD_INLINE v4 load4(const double* p) {
  v4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
TBSP_PBD_INLINE v4 vsqrt(v4 x) { return v4{__builtin_sqrt(x[0]), __builtin_sqrt(x[1]), __builtin_sqrt(x[2]), __builtin_sqrt(x[3])}; }

}  // namespace simd
}  // namespace detail
}  // namespace tbsp
