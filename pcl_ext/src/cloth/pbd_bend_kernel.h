// Internal: the dihedral bending projection of PbdClothSimulator (thesis eq. 10.3) for four
// constraints of one colour at once.
#pragma once

namespace tbsp {
namespace detail {

/// Four dihedral bending constraints, one per lane. Lane l joins the wing vertices i0[l], i1[l]
/// and the shared edge i2[l]–i3[l] (Bender's PBD convention: the angle is 0 when flat). A lane
/// with k[l] == 0 is idle (padding). The four lanes must not share a vertex (one colour).
struct BendQuad {
  int i0[4], i1[4], i2[4], i3[4];
  double rest[4];  ///< rest dihedral angle, radians
  double k[4];     ///< stiffness of this sweep, (0, 0.5]; 0: idle lane
};

/// Projects the four constraints of `q` once: each moves its four vertices (xyz interleaved in
/// `pred`, three doubles per vertex) along the gradients of Bridson et al. 2003, weighted by the
/// inverse masses `inv_mass`. A lane whose free vertices cannot change its angle, or whose edge
/// or triangles are degenerate, moves nothing. Per lane the arithmetic is exactly that of one
/// scalar projection (the same operations in the same order, no fused multiply-add): the result
/// does not depend on which lanes constraints share, nor on the CPU's vector width.
void project_bend_quad(const BendQuad& q, const double* inv_mass, double* pred);

}  // namespace detail
}  // namespace tbsp
