// PbdClothSimulator: one sub-step (external forces, prediction, constraint projection, velocity
// update) and the constraint projections of thesis eq. 10.2-10.5.
#include <algorithm>
#include <cmath>

#include "tbsp/cloth/pbd_cloth_simulator.h"
#include "pbd_bend_kernel.h"
#include "pbd_contact_kernel.h"
#include "pbd_stretch_kernel.h"

namespace tbsp {

namespace {

// Per-iteration stiffness so that n iterations of k' give the effect of one projection of k
// (Müller et al. 2007, §3.3): 1 − (1 − k)^(1/n).
double per_iteration(double k, int n) { return k >= 1 ? 1.0 : 1.0 - std::pow(1.0 - k, 1.0 / n); }

// Largest bending stiffness of one sweep: the linearised dihedral projection overshoots and
// can diverge at full stiffness (k_bend = 1 would give 1 per sweep).
constexpr double kMaxBendSweep = 0.5;

}  // namespace

void PbdClothSimulator::applyExternal(double dt) {
  const std::size_t n = pos_.size(), nf = std::size_t(F_.rows());
  // area-weighted vertex normals of the current positions (for the drag split, eq. 10.5): face
  // normals, then each vertex's sum over its faces in ascending order (as a scatter would add them)
  face_normal_.resize(nf);
  const double h = settings_.drag_constant, unit = settings_.drag_unit;
#pragma omp parallel if (n >= kParallelMin)
  {
#pragma omp for schedule(static)
  for (std::size_t f = 0; f < nf; ++f) {
    const Eigen::Vector3d& a = pos_[std::size_t(F_(Eigen::Index(f), 0))];
    face_normal_[f] = (pos_[std::size_t(F_(Eigen::Index(f), 1))] - a).cross(pos_[std::size_t(F_(Eigen::Index(f), 2))] - a);
  }
  // then drag and gravity, f_d = −½ A h (d_n |u_n|² n̂ + d_t u_t) with A = m (the acceleration is
  // f_d / m), four vertices per call of the vector kernel (pbd_stretch_kernel.cpp)
  static_assert(sizeof(Eigen::Vector3d) == 3 * sizeof(double), "vel_ is read as packed xyz");
  const double g[3] = {settings_.gravity.x(), settings_.gravity.y(), settings_.gravity.z()};
#pragma omp for schedule(static)
  for (std::size_t q4 = 0; q4 < (n + 3) / 4; ++q4) {
    detail::DragQuad q;
    for (int l = 0; l < 4; ++l) {
      const std::size_t i = 4 * q4 + std::size_t(l);
      q.active[l] = i < n && inv_mass_[i] != 0;
      q.vertex[l] = int(std::min(i, n - 1));
      Eigen::Vector3d normal = Eigen::Vector3d::Zero();
      if (q.active[l])
        for (int f = vf_offsets_[i]; f < vf_offsets_[i + 1]; ++f) normal += face_normal_[std::size_t(vf_faces_[std::size_t(f)])];
      q.nx[l] = normal.x(), q.ny[l] = normal.y(), q.nz[l] = normal.z();
      const ClothMaterial& m = materials_[std::size_t(region_(Eigen::Index(q.vertex[l])))];
      q.d_n[l] = m.d_n, q.d_t[l] = m.d_t;
    }
    detail::apply_drag_quad(q, g, h, unit, dt, vel_.data()->data());
  }
  }
}

void PbdClothSimulator::findProxyCandidates(const std::vector<RoundCone>& prev, const std::vector<RoundCone>& next,
                                            double travel) {
  const std::size_t n = pos_.size();
  proxy_pairs_.clear();
  proxy_offsets_.assign(n + 1, 0);
  if (next.empty()) return;
  // A vertex can touch proxy k during the step only if its distance to the proxy's axis segment
  // at the start, less the farthest an end point moves (every point of a linearly moving segment
  // moves less), less the larger radius, is within twice the thickness and twice the farthest
  // any vertex travels (the margins of the bounding-sphere test this replaces, which took in
  // most of a skirt around a leg: 19 % of a frame went to signed distances of far vertices).
  const std::size_t np = next.size();
  std::vector<double> reach2(np), l2(np);  // squared reach; squared axis length at the start
  std::vector<Eigen::Vector3d> ab(np);     // axis at the start
  for (std::size_t k = 0; k < np; ++k) {
    const double reach = std::max((next[k].a - prev[k].a).norm(), (next[k].b - prev[k].b).norm()) +
                         std::max({next[k].ra, next[k].rb, prev[k].ra, prev[k].rb}) + 2 * settings_.thickness + 2 * travel;
    reach2[k] = reach * reach;
    ab[k] = prev[k].b - prev[k].a;
    l2[k] = ab[k].squaredNorm();
  }
  auto reaches = [&](std::size_t i, std::size_t k) {
    const double t = l2[k] > 0 ? std::clamp((pos_[i] - prev[k].a).dot(ab[k]) / l2[k], 0.0, 1.0) : 0.0;
    return (pos_[i] - (prev[k].a + t * ab[k])).squaredNorm() < reach2[k];
  };
  // two passes over the vertices (count, then fill in vertex order), each split over threads
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (std::size_t i = 0; i < n; ++i) {
    int c = 0;
    if (inv_mass_[i] != 0)
      for (std::size_t k = 0; k < np; ++k) c += reaches(i, k);
    proxy_offsets_[i + 1] = c;
  }
  for (std::size_t i = 0; i < n; ++i) proxy_offsets_[i + 1] += proxy_offsets_[i];
  proxy_pairs_.resize(std::size_t(proxy_offsets_[n]));
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t q = std::size_t(proxy_offsets_[i]);
    if (q == std::size_t(proxy_offsets_[i + 1])) continue;
    for (std::size_t k = 0; k < np; ++k)
      if (reaches(i, k)) proxy_pairs_[q++] = {int(i), int(k)};
  }
}

void PbdClothSimulator::findSelfContacts(const std::vector<double>& travel) {
  self_pairs_.clear();
  const double s = 2 * settings_.thickness;
  if (!settings_.self_collision || s <= 0) return;
  const std::size_t n = pos_.size();
  // Two vertices can touch during the window only if |x_i − x_j| < s + travel_i + travel_j. Each
  // pair is found by its faster vertex, which searches s + 2·travel (≥ that bound) and accepts
  // only slower partners, so one fast vertex does not widen everybody's search.
  std::vector<double> sorted_travel(travel);
  std::nth_element(sorted_travel.begin(), sorted_travel.begin() + std::ptrdiff_t(n * 9 / 10), sorted_travel.end());
  // cell: the search of 90 % of the vertices stays within 3×3×3 cells; the fastest one's within 9×9×9
  const double tmax = *std::max_element(travel.begin(), travel.end());
  const double cell = std::max(s + 2 * sorted_travel[n * 9 / 10], (s + 2 * tmax) / 4);
  // uniform grid, counting sort: slot b (a cell of the dense grid below, or a hash bucket) holds
  // its vertices in increasing index order
  std::size_t buckets = 1;
  while (buckets < 2 * n) buckets <<= 1;
  auto coord = [&](const Eigen::Vector3d& p) {
    return Eigen::Vector3i(int(std::floor(p.x() / cell)), int(std::floor(p.y() / cell)), int(std::floor(p.z() / cell)));
  };
  auto hash = [&](const Eigen::Vector3i& c) {
    return (std::size_t(std::uint32_t(c.x()) * 73856093u) ^ std::size_t(std::uint32_t(c.y()) * 19349663u) ^
            std::size_t(std::uint32_t(c.z()) * 83492791u)) & (buckets - 1);
  };
  std::vector<Eigen::Vector3i> cells(n);
  for (std::size_t i = 0; i < n; ++i) cells[i] = coord(pos_[i]);
  // A dense grid over the cells' bounding box when it is small (any cloth of sane extent: the
  // bench's skirt ~40k cells): the cells of an x-row are then adjacent, so a vertex reads each
  // row in its reach as one run (~5 runs instead of 13 hashed buckets). Otherwise (a vertex far
  // from the rest) the hash.
  Eigen::Vector3i clo = cells[0], chi = cells[0];
  for (const auto& c : cells) clo = clo.cwiseMin(c), chi = chi.cwiseMax(c);
  const long long dx = (long long)chi.x() - clo.x() + 1, dy = (long long)chi.y() - clo.y() + 1, dz = (long long)chi.z() - clo.z() + 1;
  const long long cap = std::max<long long>(4096, 8 * (long long)n);  // each factor checked first: no overflow
  const bool dense = dx <= cap && dy <= cap && dz <= cap && dx * dy <= cap && dx * dy * dz <= cap;
  const std::size_t slots = dense ? std::size_t(dx * dy * dz) : buckets;
  auto slot = [&](const Eigen::Vector3i& c) {
    return dense ? std::size_t((c.x() - clo.x()) + dx * ((c.y() - clo.y()) + dy * (long long)(c.z() - clo.z()))) : hash(c);
  };
  std::vector<int> start(slots + 1, 0);
  for (std::size_t i = 0; i < n; ++i) ++start[slot(cells[i]) + 1];
  for (std::size_t b = 0; b < slots; ++b) start[b + 1] += start[b];
  // the entries in slot order as separate arrays (what the search tests first: position, travel,
  // vertex; and the cell, for the hash), so a run of slots is read as contiguous arrays and
  // tested four entries at a time (pbd_contact_kernel.cpp)
  std::vector<double> ex(n + 3), ey(n + 3), ez(n + 3), etravel(n + 3);  // + 3: the kernel reads groups of four
  std::vector<int> ej(n + 3);
  std::vector<Eigen::Vector3i> ecell(dense ? 0 : n);
  {
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t q = std::size_t(fill[slot(cells[i])]++);
      ex[q] = pos_[i].x(), ey[q] = pos_[i].y(), ez[q] = pos_[i].z(), etravel[q] = travel[i], ej[q] = int(i);
      if (!dense) ecell[q] = cells[i];
    }
  }
  const detail::ContactEntries entries{ex.data(), ey.data(), ez.data(), etravel.data(), ej.data()};
  const double exclude = 2 * s;  // rest neighbours closer than this are not contacts
  // Scratch of one block of the search: the runs of a vertex and the entries that pass the
  // kernel's tests.
  struct Scratch {
    std::vector<int> begin, end, candidates;
  };
  // The pairs vertex i finds (partners slower than it, within its reach, not rest neighbours).
  auto search = [&](std::size_t i, std::vector<std::pair<int, int>>& out, Scratch& scratch) {
    const double reach = s + 2 * travel[i], ti = travel[i];
    const Eigen::Vector3d p = pos_[i];
    const Eigen::Vector3d r = rest_.row(Eigen::Index(i)).transpose();
    const bool fixed_i = inv_mass_[i] == 0;
    // Only the cells the ball of radius `reach` around p reaches (its bounding box, then the
    // cells whose nearest point is within reach): on the bench's skirt 13 cells per vertex on
    // average instead of 27-125. The margin keeps rounding from dropping a cell that holds a
    // partner exactly at the reach.
    const double rm = reach * (1 + 1e-9) + 1e-12, rm2 = rm * rm;
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = int(std::floor((p[a] - rm) / cell));
      hi[a] = int(std::floor((p[a] + rm) / cell));
    }
    auto gap = [&](int a, int k) {  // squared distance from p to cell k along axis a (0 inside)
      const double g = k < cells[i][a] ? p[a] - (k + 1) * cell : k > cells[i][a] ? k * cell - p[a] : 0.0;
      return g > 0 ? g * g : 0.0;
    };
    // the tests the kernel leaves: a pinned pair, rest neighbours
    auto accept = [&](std::size_t j) {
      if (fixed_i && inv_mass_[j] == 0) return;
      if ((r - rest_.row(Eigen::Index(j)).transpose()).squaredNorm() < exclude * exclude) return;
      out.emplace_back(int(std::min(i, j)), int(std::max(i, j)));
    };
    // the kernel's tests over the runs collected in scratch; the passing entries in scan order
    const double pp[3] = {p.x(), p.y(), p.z()};
    auto candidates = [&](int total) {
      if (scratch.candidates.size() < std::size_t(total) + 4) scratch.candidates.resize(std::size_t(total) + 4);
      return detail::contact_candidates(entries, scratch.begin.data(), scratch.end.data(), int(scratch.begin.size()), pp, ti, int(i),
                                        reach * reach, scratch.candidates.data());
    };
    if (dense) {  // rows of the box within reach; each row's cells x0..x1 are one run of entries
      const int x0 = std::max(lo[0], clo.x()), x1 = std::min(hi[0], chi.x());
      if (x0 > x1) return;
      scratch.begin.clear(), scratch.end.clear();
      int total = 0;
      for (int y = std::max(lo[1], clo.y()); y <= std::min(hi[1], chi.y()); ++y) {
        const double gy = gap(1, y);
        if (gy > rm2) continue;
        for (int z = std::max(lo[2], clo.z()); z <= std::min(hi[2], chi.z()); ++z) {
          if (gy + gap(2, z) > rm2) continue;
          const std::size_t row = slot(Eigen::Vector3i(x0, y, z));
          scratch.begin.push_back(start[row]);
          scratch.end.push_back(start[row + std::size_t(x1 - x0) + 1]);
          total += scratch.end.back() - scratch.begin.back();
        }
      }
      const int found = candidates(total);
      for (int c = 0; c < found; ++c) accept(std::size_t(ej[std::size_t(scratch.candidates[std::size_t(c)])]));
      return;
    }
    // hash: a bucket is one run; of the entries that pass, those of other cells sharing the bucket
    // are dropped (the same entries, in the same order, as testing the cell first)
    auto visit = [&](const Eigen::Vector3i& cc) {
      const std::size_t h = hash(cc);
      scratch.begin.assign(1, start[h]);
      scratch.end.assign(1, start[h + 1]);
      const int found = candidates(start[h + 1] - start[h]);
      for (int c = 0; c < found; ++c) {
        const std::size_t q = std::size_t(scratch.candidates[std::size_t(c)]);
        if (ecell[q] == cc) accept(std::size_t(ej[q]));
      }
    };
    for (int x = lo[0]; x <= hi[0]; ++x) {
      const double gx = gap(0, x);
      if (gx > rm2) continue;
      for (int y = lo[1]; y <= hi[1]; ++y) {
        const double gxy = gx + gap(1, y);
        if (gxy > rm2) continue;
        for (int z = lo[2]; z <= hi[2]; ++z)
          if (gxy + gap(2, z) <= rm2) visit(Eigen::Vector3i(x, y, z));
      }
    }
  };
  // Parallel over fixed blocks of vertices, each block's pairs in its own list; the lists are
  // joined in block order and sorted, so the pairs (and the order projectSelf visits them in)
  // do not depend on the thread count.
  constexpr std::size_t kBlock = 256;
  const std::size_t nblocks = (n + kBlock - 1) / kBlock;
  std::vector<std::vector<std::pair<int, int>>> found(nblocks);
#pragma omp parallel for schedule(dynamic, 1) if (n >= kParallelMin)
  for (std::size_t b = 0; b < nblocks; ++b) {
    Scratch scratch;
    for (std::size_t i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i) search(i, found[b], scratch);
  }
  // sorted (first, second): a counting sort by the first vertex, then each vertex's few partners
  // sorted (the same order as sorting the whole list, which took a tenth of a simulation)
  std::vector<int> first_start(n + 1, 0);
  for (const auto& f : found)
    for (const auto& pr : f) ++first_start[std::size_t(pr.first) + 1];
  for (std::size_t i = 0; i < n; ++i) first_start[i + 1] += first_start[i];
  self_pairs_.resize(std::size_t(first_start[n]));
  {
    std::vector<int> fill(first_start.begin(), first_start.end() - 1);
    for (const auto& f : found)
      for (const auto& pr : f) self_pairs_[std::size_t(fill[std::size_t(pr.first)]++)] = pr;
  }
  for (std::size_t i = 0; i < n; ++i)
    if (first_start[i + 1] - first_start[i] > 1)
      std::sort(self_pairs_.begin() + first_start[i], self_pairs_.begin() + first_start[i + 1]);
}

// The projections below run inside the sweep's parallel region (substep): each `omp for` splits
// one colour over the threads (static schedule: the same split every time) and ends in a barrier;
// outside a parallel region they run serially. Colours share no vertex, so the result does not
// depend on the thread count.
void PbdClothSimulator::projectStretch(double k) {
  // C = |p_a − p_b| − rest (eq. 10.2), four constraints of a colour per call of the vector kernel
  // (pbd_stretch_kernel.cpp); the conflict colour one at a time, in order
  double* P = pred_.data()->data();
  for (std::size_t ci = 0; ci < stretch_colours_.size(); ++ci) {
    const auto& colour = stretch_colours_[ci];
    auto project = [&](std::size_t from, int lanes) {
      detail::StretchQuad q;
      for (int l = 0; l < lanes; ++l) {
        const Stretch& c = stretch_[std::size_t(colour[from + std::size_t(l)])];
        q.a[l] = c.a, q.b[l] = c.b, q.rest[l] = c.rest;
      }
      detail::project_stretch_quad(q, lanes, k, inv_mass_.data(), P);
    };
    if (ci == stretch_conflict_colour_) {
#pragma omp single
      for (std::size_t c = 0; c < colour.size(); ++c) project(c, 1);
    } else {
#pragma omp for schedule(static)
      for (std::size_t g = 0; g < (colour.size() + 3) / 4; ++g) project(4 * g, int(std::min<std::size_t>(4, colour.size() - 4 * g)));
    }
  }
}

void PbdClothSimulator::projectBend(const std::vector<double>& kr) {
  // four constraints of a colour per call of the vector kernel (pbd_bend_kernel.cpp); the
  // conflict colour one at a time, in order
  static_assert(sizeof(Eigen::Vector3d) == 3 * sizeof(double), "pred_ is read as packed xyz");
  double* P = pred_.data()->data();
  auto set_lane = [&](detail::BendQuad& q, int l, int index) {
    const Bend& c = bend_[std::size_t(index)];
    q.i0[l] = c.c, q.i1[l] = c.d, q.i2[l] = c.a, q.i3[l] = c.b;
    q.rest[l] = c.rest;
    q.k[l] = kr[std::size_t(c.region)];
  };
  auto idle = [](detail::BendQuad& q, int from) {
    for (int l = from; l < 4; ++l) q.i0[l] = q.i1[l] = q.i2[l] = q.i3[l] = 0, q.rest[l] = 0, q.k[l] = 0;
  };
  for (std::size_t ci = 0; ci < bend_colours_.size(); ++ci) {
    const auto& colour = bend_colours_[ci];
    if (ci == bend_conflict_colour_) {
#pragma omp single
      for (int index : colour) {
        detail::BendQuad q;
        set_lane(q, 0, index);
        idle(q, 1);
        detail::project_bend_quad(q, inv_mass_.data(), P);
      }
    } else {
      const std::size_t quads = (colour.size() + 3) / 4;
#pragma omp for schedule(static)
      for (std::size_t g = 0; g < quads; ++g) {
        detail::BendQuad q;
        const int lanes = int(std::min<std::size_t>(4, colour.size() - 4 * g));
        for (int l = 0; l < lanes; ++l) set_lane(q, l, colour[4 * g + std::size_t(l)]);
        idle(q, lanes);
        detail::project_bend_quad(q, inv_mass_.data(), P);
      }
    }
  }
}

void PbdClothSimulator::projectTethers() {
  if (!settings_.tethers) return;
  const std::size_t n = pred_.size();
#pragma omp for schedule(static)
  for (std::size_t i = 0; i < n; ++i) {
    const int a = tether_anchor_[i];
    if (a < 0 || inv_mass_[i] == 0) continue;
    const Eigen::Vector3d d = pred_[i] - pred_[std::size_t(a)];
    const double len = d.norm();
    if (len > tether_length_[i]) pred_[i] = pred_[std::size_t(a)] + (tether_length_[i] / len) * d;
  }
}

void PbdClothSimulator::projectBlend(const Points& targets, const std::vector<double>& k_blend) {
  const std::size_t n = pred_.size();
#pragma omp for schedule(static)
  for (std::size_t i = 0; i < n; ++i)
    if (inv_mass_[i] != 0 && k_blend[i] > 0) pred_[i] += k_blend[i] * (targets[i] - pred_[i]);
}

void PbdClothSimulator::projectProxies(const std::vector<RoundCone>& prev, const std::vector<RoundCone>& cur) {
  if (proxy_pairs_.empty()) return;
  const std::size_t n = pred_.size();
  const double th = settings_.thickness, mu = settings_.friction;
  // Up to four passes over a vertex's proxies: where proxies overlap (a crease between hip and
  // thigh) pushing out of one can push into the other.
#pragma omp for schedule(static)
  for (std::size_t i = 0; i < n; ++i)
    for (int pass = 0, moved = 1; pass < 4 && moved; ++pass) {
      moved = 0;
      for (int q = proxy_offsets_[i]; q < proxy_offsets_[i + 1]; ++q) {
      const std::size_t k = std::size_t(proxy_pairs_[std::size_t(q)].second);
      Eigen::Vector3d nrm;
      const double sd = cur[k].signedDistance(pred_[i], &nrm);
      if (sd >= th * (1 - 1e-9)) continue;
      moved = 1;
      const double depth = th - sd;
      pred_[i] += depth * nrm;
      if (mu <= 0) continue;
      // Coulomb friction on the slide relative to the proxy surface during this sub-step
      const Eigen::Vector3d ab = cur[k].b - cur[k].a;
      const double t = ab.squaredNorm() > 0 ? std::clamp((pred_[i] - cur[k].a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
      const Eigen::Vector3d surface = (1 - t) * (cur[k].a - prev[k].a) + t * (cur[k].b - prev[k].b);
      const Eigen::Vector3d slide = (pred_[i] - pos_[i]) - surface;
      const Eigen::Vector3d tang = slide - slide.dot(nrm) * nrm;
      const double len = tang.norm();
      if (len < mu * depth) pred_[i] -= tang;
      else if (len > 0) pred_[i] -= (mu * depth / len) * tang;
      }
    }
}

void PbdClothSimulator::projectSelf() {
  const double s = 2 * settings_.thickness;
  for (const auto& [i, j] : self_pairs_) {
    const double wi = inv_mass_[std::size_t(i)], wj = inv_mass_[std::size_t(j)];
    Eigen::Vector3d d = pred_[std::size_t(i)] - pred_[std::size_t(j)];
    const double len = d.norm();
    if (len >= s || len < 1e-12 || wi + wj == 0) continue;
    const Eigen::Vector3d corr = ((s - len) / ((wi + wj) * len)) * d;
    pred_[std::size_t(i)] += wi * corr;
    pred_[std::size_t(j)] -= wj * corr;
  }
}

void PbdClothSimulator::contactVelocities(const std::vector<RoundCone>& prev, const std::vector<RoundCone>& cur, double dt) {
  const std::size_t n = pos_.size();
  const double th = settings_.thickness;
  int contacts = 0;
#pragma omp parallel for schedule(static) reduction(+ : contacts) if (n >= kParallelMin)
  for (std::size_t i = 0; i < n; ++i) {
    int best = -1;
    double best_sd = std::numeric_limits<double>::infinity();
    Eigen::Vector3d best_n = Eigen::Vector3d::Zero();
    for (int q = proxy_offsets_[i]; q < proxy_offsets_[i + 1]; ++q) {
      const int k = proxy_pairs_[std::size_t(q)].second;
      Eigen::Vector3d nrm;
      const double sd = cur[std::size_t(k)].signedDistance(pos_[i], &nrm);
      if (sd < best_sd) best_sd = sd, best = k, best_n = nrm;
    }
    if (best < 0 || best_sd > th * 1.01 + 1e-12) continue;
    ++contacts;
    // surface velocity: the cone's axis point nearest the vertex, moved between sub-steps
    const RoundCone& c = cur[std::size_t(best)];
    const RoundCone& p = prev[std::size_t(best)];
    const Eigen::Vector3d ab = c.b - c.a;
    const double t = ab.squaredNorm() > 0 ? std::clamp((pos_[i] - c.a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
    const Eigen::Vector3d vs = ((1 - t) * (c.a - p.a) + t * (c.b - p.b)) / dt;
    const Eigen::Vector3d rel = vel_[i] - vs;
    const double vn = rel.dot(best_n);
    const Eigen::Vector3d vt = rel - vn * best_n;
    const double vn_new = vn < 0 ? -settings_.restitution * vn : vn;
    vel_[i] = vs + vn_new * best_n + vt;
  }
  proxy_contacts_ = contacts;
}

void PbdClothSimulator::substep(const Eigen::MatrixX3d& targets, const std::vector<RoundCone>& prev,
                                const std::vector<RoundCone>& cur, double t1, double dt) {
  const std::size_t n = pos_.size();
  // targets at the end of this sub-step
  Points& tgt = sub_targets_;
  tgt.resize(n);
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (std::size_t i = 0; i < n; ++i)
    tgt[i] = ((1 - t1) * targets_prev_.row(Eigen::Index(i)) + t1 * targets.row(Eigen::Index(i))).transpose();

  applyExternal(dt);
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (std::size_t i = 0; i < n; ++i) pred_[i] = inv_mass_[i] != 0 ? Eigen::Vector3d(pos_[i] + dt * vel_[i]) : tgt[i];
  const int it = settings_.iterations;
  const int sweeps = it * settings_.substeps;  // stiffnesses are per frame: n_iter sweeps in total
  const double ks = per_iteration(settings_.k_stretch, sweeps);
  std::vector<double> kb(materials_.size());
  for (std::size_t r = 0; r < materials_.size(); ++r) kb[r] = std::min(kMaxBendSweep, per_iteration(materials_[r].k_bend, sweeps));
  if (k_blend_.size() != n || k_blend_sweeps_ != sweeps) {  // δ or the sweep count changed: recompute
    k_blend_.resize(n);
    for (std::size_t i = 0; i < n; ++i) k_blend_[i] = per_iteration(1 - delta_(Eigen::Index(i)), sweeps);
    k_blend_sweeps_ = sweeps;
  }
  const std::vector<double>& k_blend = k_blend_;

#pragma omp parallel if (n >= kParallelMin)
  for (int iter = 0; iter < it; ++iter) {
    projectStretch(ks);
    projectTethers();
    projectBend(kb);
    projectBlend(tgt, k_blend);
#pragma omp single
    projectSelf();
    projectProxies(prev, cur);  // last: collisions with the body are hard constraints
  }
  int self = 0;
  const double s = 2 * settings_.thickness;
  const std::size_t np = self_pairs_.size();
#pragma omp parallel for schedule(static) reduction(+ : self) if (np >= kParallelMin)
  for (std::size_t q = 0; q < np; ++q)
    self += (pred_[std::size_t(self_pairs_[q].first)] - pred_[std::size_t(self_pairs_[q].second)]).norm() < s * 1.01;
  self_contacts_ = self;

#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (std::size_t i = 0; i < n; ++i) {
    vel_[i] = (pred_[i] - pos_[i]) / dt;
    pos_[i] = pred_[i];
  }
  contactVelocities(prev, cur, dt);
}

}  // namespace tbsp
