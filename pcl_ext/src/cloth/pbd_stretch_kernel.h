// Internal: PbdClothSimulator's stretch projection (thesis eq. 10.2) for four constraints of one
// colour at once, and its drag and gravity (eq. 10.5) for four vertices at once.
#pragma once

namespace tbsp {
namespace detail {

/// Four distance constraints, one per lane: vertices a[l] and b[l] kept `rest[l]` apart (metres).
/// Lanes ≥ `lanes` are idle. The lanes must not share a vertex (one colour).
struct StretchQuad {
  int a[4], b[4];
  double rest[4];
};

/// Projects the first `lanes` (1..4) constraints of `q` once at stiffness k ∈ (0, 1]: each moves
/// its two vertices (xyz interleaved in `pred`) along their difference, weighted by the inverse
/// masses `inv_mass`; a constraint between two pinned vertices or two coincident ones (closer
/// than 1e-12 m) moves nothing. Per lane exactly the scalar projection's arithmetic (Eigen's
/// order, no fused multiply-add): the bits do not depend on the lanes' neighbours or the CPU.
void project_stretch_quad(const StretchQuad& q, int lanes, double k, const double* inv_mass, double* pred);

/// Drag and gravity of four vertices, one per lane (eq. 10.5 with A = m, so the acceleration is
/// g − ½ h (d_n |u_n|/unit · u_n + d_t u_t)), where u_n, u_t are the velocity's parts along and
/// across the summed face normal `normal` (no drag where that is zero or h is 0). Lanes with
/// active[l] == 0 are left alone; the others get vel += dt · acc (xyz interleaved in `vel`, vertex
/// index vertex[l]). Per lane exactly the scalar code's arithmetic.
struct DragQuad {
  int vertex[4];
  int active[4];
  double nx[4], ny[4], nz[4];  ///< summed area-weighted face normals
  double d_n[4], d_t[4];       ///< the lane's material
};
void apply_drag_quad(const DragQuad& q, const double gravity[3], double h, double unit, double dt, double* vel);

}  // namespace detail
}  // namespace tbsp
