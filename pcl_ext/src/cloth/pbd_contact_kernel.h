// Internal: the first tests of PbdClothSimulator's self-contact search (which entries of the
// contact grid can pair with a vertex), four entries at a time.
#pragma once

namespace tbsp {
namespace detail {

/// The contact grid's entries as separate arrays (entry q: position x[q], y[q], z[q], the
/// distance `travel[q]` its vertex can travel in the window, its vertex index j[q]). Each array
/// has 3 readable elements after the last entry (the kernel reads whole groups of four).
struct ContactEntries {
  const double* x;
  const double* y;
  const double* z;
  const double* travel;
  const int* j;
};

/// Scans the runs [begin[r], end[r]) of `e`, r < runs, in order, for the partners vertex `i`
/// (at p, travel `ti`) looks for: an entry q passes unless travel[q] > ti, or travel[q] == ti and
/// j[q] ≥ i (the pair is then found from j[q], or j[q] is i itself), or its squared distance to
/// p, computed as (dx² + dy²) + dz², exceeds `reach2`. Writes the passing q in scan order to
/// `out` (room for every entry of the runs and 4 more) and returns their count. Exactly the scalar tests:
/// no fused multiply-add, so the AVX2 clone and the baseline pass the same entries.
int contact_candidates(const ContactEntries& e, const int* begin, const int* end, int runs, const double p[3], double ti, int i,
                       double reach2, int* out);

}  // namespace detail
}  // namespace tbsp
