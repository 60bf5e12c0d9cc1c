// The self-contact search's candidate tests on four grid entries at once (GCC/Clang vector
// extensions). The search was 36-39 % of a simulation after the dense grid (bench_cloth,
// 2026-12-05): per vertex ~34 entries tested in ~5 runs, 4 within reach; the cost is the scalar
// test of each entry. Compiled like the bending kernel (-ffp-contract=off: the AVX2 clone rounds
// as the baseline does).
#include "pbd_contact_kernel.h"

#include <cstdint>
#include <cstring>

#include "pbd_simd.h"

namespace tbsp {
namespace detail {

namespace {

using namespace simd;  // v4, m4, splat, load4, vsqrt (pbd_simd.h)
typedef std::int32_t i4 __attribute__((vector_size(16)));

}  // namespace

TBSP_PBD_CLONES int contact_candidates(const ContactEntries& e, const int* begin, const int* end, int runs, const double p[3],
                                           double ti, int i, double reach2, int* out) {
  const v4 px{p[0], p[0], p[0], p[0]}, py{p[1], p[1], p[1], p[1]}, pz{p[2], p[2], p[2], p[2]};
  const v4 vt{ti, ti, ti, ti}, vr{reach2, reach2, reach2, reach2};
  const m4 vi{i, i, i, i};
  const m4 lane{0, 1, 2, 3}, bit{1, 2, 4, 8};
  // for each 4-bit lane mask, the passing lanes first (the entries are written compacted)
  static const unsigned char kFirst[16][4] = {{0, 0, 0, 0}, {0, 0, 0, 0}, {1, 0, 0, 0}, {0, 1, 0, 0}, {2, 0, 0, 0}, {0, 2, 0, 0},
                                             {1, 2, 0, 0}, {0, 1, 2, 0}, {3, 0, 0, 0}, {0, 3, 0, 0}, {1, 3, 0, 0}, {0, 1, 3, 0},
                                             {2, 3, 0, 0}, {0, 2, 3, 0}, {1, 2, 3, 0}, {0, 1, 2, 3}};
  int n = 0;
  for (int r = 0; r < runs; ++r)
    for (int q = begin[r], stop = end[r]; q < stop; q += 4) {  // the last group reads into the padding, masked
      const v4 tr = load4(e.travel + q);
      i4 j32;
      std::memcpy(&j32, e.j + q, sizeof j32);
      const m4 j = __builtin_convertvector(j32, m4);
      const v4 dx = px - load4(e.x + q), dy = py - load4(e.y + q), dz = pz - load4(e.z + q);
      const v4 d2 = (dx * dx + dy * dy) + dz * dz;  // Eigen's squaredNorm order
      const m4 left = m4{stop - q, stop - q, stop - q, stop - q};
      const m4 keep = ~(tr > vt) & ~((tr == vt) & (j >= vi)) & ~(d2 > vr) & (lane < left);
      const m4 w = keep & bit;
      const int mask = int(w[0] | w[1] | w[2] | w[3]);
      const unsigned char* first = kFirst[mask];
      out[n] = q + first[0], out[n + 1] = q + first[1], out[n + 2] = q + first[2], out[n + 3] = q + first[3];
      n += __builtin_popcount(unsigned(mask));
    }
  return n;
}

}  // namespace detail
}  // namespace tbsp
