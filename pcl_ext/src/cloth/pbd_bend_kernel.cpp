// The dihedral bending projection on four constraints at once (GCC/Clang vector extensions).
// Bending was a third of a simulation in scalar code (bench_cloth, 2026-12-05): two cross
// products, a dozen divisions and square roots per constraint, independent within a colour.
//
// Compiled with -ffp-contract=off and -fno-math-errno (pcl_ext/CMakeLists.txt): no fused
// multiply-add, so every lane rounds exactly as the scalar projection did (Eigen's operation
// order is reproduced below), and the AVX2 clone gives the same bits as the baseline.
#include "pbd_bend_kernel.h"

#include <cmath>
#include <cstddef>

#include "pbd_simd.h"

namespace tbsp {
namespace detail {

namespace {

using namespace simd;  // v4, m4, splat, vsqrt (pbd_simd.h)
TBSP_PBD_INLINE v4 select(m4 m, v4 a, v4 b) { return (v4)(((m4)a & m) | ((m4)b & ~m)); }
TBSP_PBD_INLINE v4 vabs(v4 x) { return select(x < splat(0), -x, x); }

struct V3 {
  v4 x, y, z;
};
TBSP_PBD_INLINE V3 operator-(const V3& a, const V3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
TBSP_PBD_INLINE V3 operator*(v4 s, const V3& a) { return {s * a.x, s * a.y, s * a.z}; }
TBSP_PBD_INLINE V3 operator+(const V3& a, const V3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
// Eigen's order: (x·x' + y·y') + z·z'
TBSP_PBD_INLINE v4 dot(const V3& a, const V3& b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
// Eigen's cross3: (a1 b2 − a2 b1, a2 b0 − a0 b2, a0 b1 − a1 b0)
TBSP_PBD_INLINE V3 cross(const V3& a, const V3& b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }

TBSP_PBD_INLINE V3 gather(const double* p, const int* i) {
  const double *a = p + 3 * std::ptrdiff_t(i[0]), *b = p + 3 * std::ptrdiff_t(i[1]), *c = p + 3 * std::ptrdiff_t(i[2]),
               *d = p + 3 * std::ptrdiff_t(i[3]);
  return {v4{a[0], b[0], c[0], d[0]}, v4{a[1], b[1], c[1], d[1]}, v4{a[2], b[2], c[2], d[2]}};
}
TBSP_PBD_INLINE v4 gather1(const double* w, const int* i) { return v4{w[i[0]], w[i[1]], w[i[2]], w[i[3]]}; }

// acos to within 7e-5 rad (Abramowitz & Stegun 4.4.45), as the scalar projection's fast_acos
TBSP_PBD_INLINE v4 fast_acos(v4 x) {
  const v4 a = vabs(x);
  const v4 r = vsqrt(splat(1.0) - a) * (splat(1.5707288) + a * (splat(-0.2121144) + a * (splat(0.0742610) - splat(0.0187293) * a)));
  return select(x >= splat(0), r, splat(M_PI) - r);
}

}  // namespace

TBSP_PBD_CLONES void project_bend_quad(const BendQuad& q, const double* inv_mass, double* pred) {
  // Bender's PBD dihedral constraint (gradients of Bridson et al. 2003): p2-p3 the edge, p0 and
  // p1 the wings; φ = acos(n1·n2), C = φ − φ_rest (eq. 10.3)
  const V3 p0 = gather(pred, q.i0), p1 = gather(pred, q.i1), p2 = gather(pred, q.i2), p3 = gather(pred, q.i3);
  const v4 w0 = gather1(inv_mass, q.i0), w1 = gather1(inv_mass, q.i1), w2 = gather1(inv_mass, q.i2), w3 = gather1(inv_mass, q.i3);
  const v4 k{q.k[0], q.k[1], q.k[2], q.k[3]}, rest{q.rest[0], q.rest[1], q.rest[2], q.rest[3]};
  m4 ok = (k != splat(0)) & (((w0 + w1) + w2) + w3 != splat(0));
  const V3 e = p3 - p2;
  const v4 elen = vsqrt(dot(e, e));
  ok &= ~(elen < splat(1e-12));
  V3 n1 = cross(p2 - p0, p3 - p0), n2 = cross(p3 - p1, p2 - p1);
  const v4 n1s = dot(n1, n1), n2s = dot(n2, n2);
  ok &= ~(n1s < splat(1e-30)) & ~(n2s < splat(1e-30));
  n1 = {n1.x / n1s, n1.y / n1s, n1.z / n1s};
  n2 = {n2.x / n2s, n2.y / n2s, n2.z / n2s};
  const V3 d0 = elen * n1, d1 = elen * n2;
  const V3 d2 = (dot(p0 - p3, e) / elen) * n1 + (dot(p1 - p3, e) / elen) * n2;
  const V3 d3 = (dot(p2 - p0, e) / elen) * n1 + (dot(p2 - p1, e) / elen) * n2;
  // cos φ = N1·N2 / (|N1||N2|); here n = N/|N|², so |n1||n2| = 1/(|N1||N2|)
  v4 cosphi = dot(n1, n2) / vsqrt(dot(n1, n1) * dot(n2, n2));
  cosphi = select(cosphi < -1, splat(-1), cosphi);  // std::clamp(cosphi, -1, 1)
  cosphi = select(splat(1) < cosphi, splat(1), cosphi);
  const v4 phi = fast_acos(cosphi);
  const v4 s0 = dot(d0, d0), s1 = dot(d1, d1), s2 = dot(d2, d2), s3 = dot(d3, d3);
  v4 lambda = ((w0 * s0 + w1 * s1) + w2 * s2) + w3 * s3;
  // the free vertices cannot change the angle: the linearised step would be unbounded
  v4 wmax = select(w0 < w1, w1, w0);
  wmax = select(wmax < w2, w2, wmax);
  wmax = select(wmax < w3, w3, wmax);
  ok &= ~(lambda <= splat(1e-6) * wmax * (((s0 + s1) + s2) + s3));
  lambda = (phi - rest) / lambda * k;
  lambda = select(dot(cross(n1, n2), e) > splat(0), -lambda, lambda);
  const V3 u0 = p0 - (w0 * lambda) * d0, u1 = p1 - (w1 * lambda) * d1, u2 = p2 - (w2 * lambda) * d2, u3 = p3 - (w3 * lambda) * d3;
  for (int l = 0; l < 4; ++l) {
    if (!ok[l]) continue;
    double* a = pred + 3 * std::ptrdiff_t(q.i0[l]);
    a[0] = u0.x[l], a[1] = u0.y[l], a[2] = u0.z[l];
    double* b = pred + 3 * std::ptrdiff_t(q.i1[l]);
    b[0] = u1.x[l], b[1] = u1.y[l], b[2] = u1.z[l];
    double* c = pred + 3 * std::ptrdiff_t(q.i2[l]);
    c[0] = u2.x[l], c[1] = u2.y[l], c[2] = u2.z[l];
    double* d = pred + 3 * std::ptrdiff_t(q.i3[l]);
    d[0] = u3.x[l], d[1] = u3.y[l], d[2] = u3.z[l];
  }
}

}  // namespace detail
}  // namespace tbsp
