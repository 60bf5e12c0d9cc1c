// The stretch projection and the drag of PbdClothSimulator on four lanes at once (GCC/Clang
// vector extensions). After the bending and contact kernels they were 9 % and 11 % of the
// default bench_cloth row (perf, 1 thread, 2026-12-05), the drag's samples on the latencies of
// its two square roots and three divisions per vertex. Compiled like the other kernels
// (-ffp-contract=off, -fno-math-errno): every lane rounds exactly as the scalar code did.
#include "pbd_stretch_kernel.h"

#include <cstddef>

#include "pbd_simd.h"

namespace tbsp {
namespace detail {

namespace {

using namespace simd;  // v4, m4, splat, load4, vsqrt (pbd_simd.h)

}  // namespace

TBSP_PBD_CLONES void project_stretch_quad(const StretchQuad& q, int lanes, double k, const double* inv_mass, double* pred) {
  v4 ax, ay, az, bx, by, bz, wa, wb, rest;
  for (int l = 0; l < 4; ++l) {
    const int la = l < lanes ? l : 0;  // idle lanes repeat lane 0 (never stored; their fields may be unset)
    const double* a = pred + 3 * std::ptrdiff_t(q.a[la]);
    const double* b = pred + 3 * std::ptrdiff_t(q.b[la]);
    ax[l] = a[0], ay[l] = a[1], az[l] = a[2];
    bx[l] = b[0], by[l] = b[1], bz[l] = b[2];
    wa[l] = inv_mass[q.a[la]], wb[l] = inv_mass[q.b[la]];
    rest[l] = q.rest[la];
  }
  const v4 dx = ax - bx, dy = ay - by, dz = az - bz;
  const v4 len = vsqrt((dx * dx + dy * dy) + dz * dz);
  const v4 w = wa + wb;
  const m4 ok = (w != splat(0)) & ~(len < splat(1e-12));
  // (k (len − rest) / ((wa + wb) len)) d, then pa −= wa·corr, pb += wb·corr
  const v4 s = (splat(k) * (len - rest)) / (w * len);
  const v4 cx = s * dx, cy = s * dy, cz = s * dz;
  const v4 ux = ax - wa * cx, uy = ay - wa * cy, uz = az - wa * cz;
  const v4 vx = bx + wb * cx, vy = by + wb * cy, vz = bz + wb * cz;
  for (int l = 0; l < lanes; ++l) {
    if (!ok[l]) continue;
    double* a = pred + 3 * std::ptrdiff_t(q.a[l]);
    a[0] = ux[l], a[1] = uy[l], a[2] = uz[l];
    double* b = pred + 3 * std::ptrdiff_t(q.b[l]);
    b[0] = vx[l], b[1] = vy[l], b[2] = vz[l];
  }
}

TBSP_PBD_CLONES void apply_drag_quad(const DragQuad& q, const double gravity[3], double h, double unit, double dt, double* vel) {
  v4 ux, uy, uz;
  for (int l = 0; l < 4; ++l) {
    const double* u = vel + 3 * std::ptrdiff_t(q.vertex[l]);
    ux[l] = u[0], uy[l] = u[1], uz[l] = u[2];
  }
  const v4 nx = load4(q.nx), ny = load4(q.ny), nz = load4(q.nz);
  const v4 len = vsqrt((nx * nx + ny * ny) + nz * nz);
  const m4 drag = (len > splat(0)) & (splat(h) > splat(0));
  const v4 nnx = nx / len, nny = ny / len, nnz = nz / len;
  const v4 dot = (ux * nnx + uy * nny) + uz * nnz;
  const v4 unx = dot * nnx, uny = dot * nny, unz = dot * nnz;
  const v4 utx = ux - unx, uty = uy - uny, utz = uz - unz;
  const v4 un_len = vsqrt((unx * unx + uny * uny) + unz * unz);
  const v4 a = (load4(q.d_n) * un_len) / splat(unit), dt_ = load4(q.d_t), c = splat(0.5 * h);
  const v4 gx = splat(gravity[0]), gy = splat(gravity[1]), gz = splat(gravity[2]);
  const v4 dragx = gx - c * (a * unx + dt_ * utx), dragy = gy - c * (a * uny + dt_ * uty), dragz = gz - c * (a * unz + dt_ * utz);
  for (int l = 0; l < 4; ++l) {
    if (!q.active[l]) continue;
    const bool d = drag[l] != 0;
    double* u = vel + 3 * std::ptrdiff_t(q.vertex[l]);
    u[0] = ux[l] + dt * (d ? dragx[l] : gx[l]);
    u[1] = uy[l] + dt * (d ? dragy[l] : gy[l]);
    u[2] = uz[l] + dt * (d ? dragz[l] : gz[l]);
  }
}

}  // namespace detail
}  // namespace tbsp
