#include "tbsp/fitting/inverse_texture_mapping.h"

#include "texture_grid.h"

#include <Eigen/Dense>
#include <nanoflann.hpp>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <spdlog/fmt/fmt.h>
#include <string>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/core/logging.h"
#include "tbsp/mesh/heat_geodesics.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp {

using namespace detail;  // texture_grid.h


bool InverseTextureMappingOptions::isValid(std::string* why) const {
  // omega below ~1e-4 loses the constraints (measured on the sample bar: max residual 0.03 px at
  // 1e-4, 34 px at 1e-6, 6e6 px at 1e-8, not positive definite at 1e-12)
  const bool ok = omega >= 1e-3 && sigma >= 0 && std::isfinite(sigma) && epsilon_factor > 0 && ratio_low > 0 && ratio_high > ratio_low &&
                  max_solve_nodes >= 16 && max_geodesic_nodes >= 16 && heat_time_factor > 0 && local_channels >= 0 &&
                  std::isfinite(normal_offset) && std::isfinite(omega) && std::isfinite(epsilon_factor) &&
                  std::isfinite(ratio_high) && std::isfinite(heat_time_factor);
  if (!ok && why)
    *why = "need finite omega >= 0.001, sigma >= 0, epsilon_factor > 0, 0 < ratio_low < ratio_high, max_solve_nodes and "
           "max_geodesic_nodes >= 16, heat_time_factor > 0, local_channels >= 0, finite normal_offset";
  return ok;
}

void InverseTextureMapping::setOptions(const InverseTextureMappingOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::InverseTextureMapping::setOptions] " + why);
  options_ = o;
}

TextureMappingResult InverseTextureMapping::compute() const {
  const auto t_start = Clock::now();
  const InverseTextureMappingOptions& o = options_;
  const std::string who = "[tbsp::InverseTextureMapping::compute]";
  // ---------------------------------------------------------------- validation
  if (width_ < 2 || height_ < 2)
    throw InvalidInput(who + " image size " + std::to_string(width_) + "x" + std::to_string(height_) + " is too small: the image must have at least 2x2 pixels (setImageSize)");
  if (!mask_.empty() && mask_.size() != static_cast<std::size_t>(width_) * height_)
    throw InvalidInput(who + " the mask has " + std::to_string(mask_.size()) + " entries but the image has " +
                       std::to_string(static_cast<long>(width_) * height_) + " pixels; give a mask of the image's size");
  MeshRequirements req;
  req.allow_nonmanifold = false;
  req.allow_boundary = true;
  require_valid_mesh(mesh_, req, "tbsp::InverseTextureMapping::compute");
  const int k = static_cast<int>(constraints_.size());
  if (k < 3) throw InvalidInput(who + " " + std::to_string(k) + " constraint(s) given; at least 3 (not on one line) are needed to place the image");
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput(who + " invalid options: " + why);
  const Eigen::MatrixX3d& V = mesh_.V;
  const Eigen::MatrixX3i& F = mesh_.F;
  const long nv = V.rows();
  const double diag = bbox_diagonal(V);
  if (std::abs(o.normal_offset) > diag)
    throw InvalidInput(fmt::format("{} normal_offset = {} is beyond the mesh's size (bbox diagonal {}); a draping offset is a small "
                                   "fraction of it (a cloth's distance from the body)",
                                   who, o.normal_offset, diag));
  std::vector<Eigen::Vector3d> at(static_cast<std::size_t>(k));  // each constraint's mesh point
  for (int c = 0; c < k; ++c) {
    const TextureConstraint& tc = constraints_[c];
    const std::string name = who + " constraint " + std::to_string(c) + " (pixel " + px(tc.pixel) + ")";
    if (!tc.pixel.allFinite() || tc.pixel.x() < 0 || tc.pixel.y() < 0 || tc.pixel.x() > width_ - 1 || tc.pixel.y() > height_ - 1)
      throw InvalidInput(name + ": the pixel is outside the " + std::to_string(width_) + "x" + std::to_string(height_) +
                         " image; pixel coordinates run from 0 to width-1 / height-1");
    if (!mask_.empty()) {
      const int xi = static_cast<int>(std::lround(tc.pixel.x())), yi = static_cast<int>(std::lround(tc.pixel.y()));
      if (!mask_[static_cast<std::size_t>(yi) * width_ + xi]) throw InvalidInput(name + ": the pixel is outside the mask; put pattern constraints on pattern pixels");
    }
    if (tc.vertex >= 0) {
      if (tc.vertex >= nv) throw InvalidInput(name + ": vertex " + std::to_string(tc.vertex) + " does not exist (the mesh has " + std::to_string(nv) + " vertices)");
    } else {
      if (tc.face < 0 || tc.face >= F.rows())
        throw InvalidInput(name + ": needs a vertex index or a face index; face " + std::to_string(tc.face) + " does not exist (the mesh has " + std::to_string(F.rows()) + " faces)");
      if (!tc.barycentric.allFinite() || tc.barycentric.minCoeff() < -1e-6 || std::abs(tc.barycentric.sum() - 1) > 1e-6)
        throw InvalidInput(name + ": barycentric coordinates must be >= 0 and sum to 1");
    }
    for (int c2 = 0; c2 < c; ++c2)
      if ((constraints_[c2].pixel - tc.pixel).norm() < 0.5)
        throw InvalidInput(name + ": the same pixel as constraint " + std::to_string(c2) + "; one pixel cannot go to two places");
    Eigen::Vector3d& p = at[static_cast<std::size_t>(c)];
    if (tc.vertex >= 0) {
      p = V.row(tc.vertex).transpose();
    } else {
      p.setZero();
      for (int a = 0; a < 3; ++a) p += tc.barycentric(a) * V.row(F(tc.face, a)).transpose();
    }
    for (int c2 = 0; c2 < c; ++c2)
      if ((at[static_cast<std::size_t>(c2)] - p).norm() <= 1e-9 * diag)
        throw InvalidInput(name + ": the same mesh point as constraint " + std::to_string(c2) + " (pixel " +
                           px(constraints_[c2].pixel) + "); one point of the mesh cannot take two pixels");
  }
  report_progress(o.progress, 0.0, "texture: setup");

  TextureMappingResult res;
  TextureMappingReport& rep = res.report;
  rep.constraints = k;
  rep.mesh_vertices = nv;
  rep.pixels = static_cast<long>(width_) * height_;

  // Constraint targets (with the draping offset along the normals).
  const Eigen::MatrixX3d VN = vertex_normals(V, F);
  std::vector<Eigen::Vector3d> target(k);
  std::vector<WeightedSource> mesh_src(k);
  for (int c = 0; c < k; ++c) {
    const TextureConstraint& tc = constraints_[c];
    if (tc.vertex >= 0) {
      target[c] = V.row(tc.vertex).transpose() + o.normal_offset * VN.row(tc.vertex).transpose();
      mesh_src[c] = {{tc.vertex, 1.0}};
    } else {
      Eigen::Vector3d p = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
      for (int a = 0; a < 3; ++a) {
        p += tc.barycentric(a) * V.row(F(tc.face, a)).transpose();
        n += tc.barycentric(a) * VN.row(F(tc.face, a)).transpose();
        mesh_src[c].emplace_back(F(tc.face, a), tc.barycentric(a));
      }
      target[c] = p + o.normal_offset * n.normalized();
    }
  }

  // ---------------------------------------------------------------- solve grid
  // A grid of at most ~max_nodes nodes spanning the whole image; nodes inside the mask.
  auto make_grid = [&](long max_nodes) {
    Grid gr;
    const double s = std::max(1.0, std::sqrt(static_cast<double>(width_) * height_ / static_cast<double>(max_nodes)));
    gr.w = std::max(2, static_cast<int>(std::lround((width_ - 1) / s)) + 1);
    gr.h = std::max(2, static_cast<int>(std::lround((height_ - 1) / s)) + 1);
    gr.sx = (width_ - 1.0) / (gr.w - 1);
    gr.sy = (height_ - 1.0) / (gr.h - 1);
    std::vector<char> on(static_cast<std::size_t>(gr.w) * gr.h, 1);
    if (!mask_.empty())
      for (int j = 0; j < gr.h; ++j)
        for (int i = 0; i < gr.w; ++i) {
          const long xi = std::lround(i * gr.sx), yi = std::lround(j * gr.sy);
          on[static_cast<std::size_t>(j) * gr.w + i] = mask_[static_cast<std::size_t>(yi) * width_ + xi] != 0;
        }
    gr.finalize(on);
    return gr;
  };
  const Grid g = make_grid(o.max_solve_nodes);
  if (g.active() == 0) throw InvalidInput(who + " the mask leaves no pattern region of at least 2x2 grid nodes; check the mask image");
  rep.grid_nodes = g.active();
  rep.pixels_per_node = std::sqrt(g.sx * g.sy);
  res.grid_width = g.w;
  res.grid_height = g.h;
  res.node_spacing_x = g.sx;
  res.node_spacing_y = g.sy;
  res.node_index = g.index;
  res.node_pixel.resize(g.active(), 2);
  for (long a = 0; a < g.active(); ++a) res.node_pixel.row(a) = g.pixel(static_cast<int>(a)).transpose();

  std::vector<std::vector<std::pair<int, double>>> cw(k);
  for (int c = 0; c < k; ++c)
    if (!g.weights(constraints_[c].pixel, cw[c]))
      throw InvalidInput(who + " constraint " + std::to_string(c) + " (pixel " + px(constraints_[c].pixel) + ") is not inside a pattern region of the mask (too thin there); move it inwards");

  // Every connected pattern piece needs 3 constraints not on one line.
  {
    std::vector<int> comp(g.active(), -1);
    int nc = 0;
    for (long s0 = 0; s0 < g.active(); ++s0) {
      if (comp[s0] >= 0) continue;
      std::vector<int> stack{static_cast<int>(s0)};
      comp[s0] = nc;
      while (!stack.empty()) {
        const int a = stack.back();
        stack.pop_back();
        const int i = g.node_x[a], j = g.node_y[a];
        const int nb[4] = {g.at(i - 1, j), g.at(i + 1, j), g.at(i, j - 1), g.at(i, j + 1)};
        for (int b : nb)
          if (b >= 0 && comp[b] < 0) {
            comp[b] = nc;
            stack.push_back(b);
          }
      }
      ++nc;
    }
    std::vector<std::vector<Eigen::Vector2d>> pts(nc);
    for (int c = 0; c < k; ++c) pts[comp[cw[c].front().first]].push_back(constraints_[c].pixel);
    for (int p = 0; p < nc; ++p) {
      bool ok = pts[p].size() >= 3;
      if (ok) {
        Eigen::Vector2d mean = Eigen::Vector2d::Zero();
        for (const auto& q : pts[p]) mean += q;
        mean /= pts[p].size();
        Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
        for (const auto& q : pts[p]) cov += (q - mean) * (q - mean).transpose();
        ok = Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov / pts[p].size()).eigenvalues()(0) > 1.0;
      }
      if (!ok) {
        const Eigen::Vector2d where = g.pixel(static_cast<int>(std::find(comp.begin(), comp.end(), p) - comp.begin()));
        throw InvalidInput(who + " the pattern piece containing pixel " + px(where) + " has " + std::to_string(pts[p].size()) +
                           " constraint(s)" + (pts[p].size() >= 3 ? " on one line" : "") +
                           "; each piece needs at least 3 constraints not on one line (or remove the piece from the mask)");
      }
    }
  }

  // ---------------------------------------------------------------- deform 1
  // Solved on the (coarser) geodesic grid: it only has to give the texture geodesics their
  // surface, and the thin-plate solution is smooth, so the solve-grid version is its bilinear
  // interpolation (exactly the solve grid when that is small, or where a mask makes the coarse
  // grid lose thin parts).
  auto t0 = Clock::now();
  Grid gg = g.active() <= o.max_geodesic_nodes ? g : make_grid(o.max_geodesic_nodes);
  std::vector<std::vector<std::pair<int, double>>> gw(k);
  bool coarse_ok = gg.active() > 0;
  for (int c = 0; c < k && coarse_ok; ++c) coarse_ok = gg.weights(constraints_[c].pixel, gw[c]);
  std::vector<std::vector<std::pair<int, double>>> up;  // solve node -> geodesic-grid weights
  if (coarse_ok && &gg != &g && gg.active() != g.active()) {
    up.resize(g.active());
    for (long a = 0; a < g.active() && coarse_ok; ++a) coarse_ok = gg.weights(g.pixel(static_cast<int>(a)), up[a]);
  }
  if (!coarse_ok) {
    gg = g;
    up.clear();
    for (int c = 0; c < k; ++c) gw[c] = cw[c];
  }
  rep.geodesic_nodes = gg.active();
  Eigen::MatrixX3d X1;  // deform 1 on gg
  {
    NormalEquations ne(gg);
    add_thin_plate(gg, ne);
    for (int c = 0; c < k; ++c) ne.addRow(gw[c].data(), static_cast<int>(gw[c].size()), o.omega * o.omega, target[c]);
    SparseCholesky chol1;
    X1 = solve(ne, chol1, "deform 1");
  }
  if (up.empty()) {
    res.initial_surface = X1;
  } else {
    res.initial_surface.resize(g.active(), 3);
    for (long a = 0; a < g.active(); ++a) {
      Eigen::RowVector3d x = Eigen::RowVector3d::Zero();
      for (const auto& [n, w] : up[a]) x += w * X1.row(n);
      res.initial_surface.row(a) = x;
    }
  }
  rep.t_deform1 = seconds_since(t0);
  report_progress(o.progress, 0.2, "texture: mesh geodesics");

  // ---------------------------------------------------------------- mesh geodesics
  t0 = Clock::now();
  // Both distance fields get the same heat time, set by the coarser of the two surfaces (mesh
  // edges, or geodesic-grid edges on the deform-1 surface): the heat method smooths distances
  // over ~sqrt(t), and comparing fields smoothed differently biases the ratio test and the
  // matching near the constraints.
  auto mean_edge = [](const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& T) {
    double sum = 0;
    for (Eigen::Index f = 0; f < T.rows(); ++f)
      for (int c = 0; c < 3; ++c) sum += (X.row(T(f, c)) - X.row(T(f, (c + 1) % 3))).norm();
    return T.rows() ? sum / (3.0 * T.rows()) : 0.0;
  };
  const Eigen::MatrixX3i GF = gg.faces();
  const double h_heat = std::max(mean_edge(V, F), mean_edge(X1, GF));
  HeatGeodesicsOptions hopt;
  hopt.time_factor = o.heat_time_factor;
  if (h_heat > 0) hopt.time = o.heat_time_factor * h_heat * h_heat;
  const Eigen::MatrixXd FT = HeatGeodesics(V, F, hopt).distances(mesh_src);
  rep.t_mesh_geodesics = seconds_since(t0);
  report_progress(o.progress, 0.4, "texture: texture geodesics");

  // ---------------------------------------------------------------- texture geodesics
  t0 = Clock::now();
  res.surface = res.initial_surface;
  {
  t0 = Clock::now();
  const Eigen::MatrixX3d& GX = X1;
  Eigen::MatrixXd FS(gg.active(), k);
  if (o.match_distance == MatchDistance::DeformedSurface) {
    FS = HeatGeodesics(GX, GF, hopt).distances(gw);
  } else {
    // Flat-image distances scaled by the mean size of a pixel on the deformed surface.
    double len3 = 0, lenp = 0;
    for (long a = 0; a < gg.active(); ++a) {
      const int i = gg.node_x[a], j = gg.node_y[a];
      if (gg.at(i + 1, j) >= 0) { len3 += (GX.row(gg.at(i + 1, j)) - GX.row(a)).norm(); lenp += gg.sx; }
      if (gg.at(i, j + 1) >= 0) { len3 += (GX.row(gg.at(i, j + 1)) - GX.row(a)).norm(); lenp += gg.sy; }
    }
    const double scale = lenp > 0 ? len3 / lenp : 1.0;
    for (long a = 0; a < gg.active(); ++a)
      for (int c = 0; c < k; ++c) FS(a, c) = scale * (gg.pixel(static_cast<int>(a)) - constraints_[c].pixel).norm();
  }
  rep.t_texture_geodesics += seconds_since(t0);
  report_progress(o.progress, 0.6, "texture: matching");

  // ---------------------------------------------------------------- matching
  t0 = Clock::now();
  // Distance vectors at the constraints themselves (for the ratio test).
  auto FT_at = [&](int c, int ch) {
    double s = 0;
    for (const auto& [v, w] : mesh_src[c]) s += w * FT(v, ch);
    return s;
  };
  auto FS_at = [&](int c, int ch) {
    double s = 0;
    for (const auto& [a, w] : gw[c]) s += w * FS(a, ch);
    return s;
  };
  rep.dropped_channels = 0;
  rep.matched = rep.unmatched = 0;
  std::vector<std::vector<char>> keep(k, std::vector<char>(k, 1));  // keep[a][b]: channel b near constraint a
  if (o.mismatch_detection) {
    const double tiny = 1e-9 * diag;
    for (int a = 0; a < k; ++a)
      for (int b = 0; b < k; ++b) {
        if (a == b) continue;
        const double dt = FT_at(a, b), ds = FS_at(a, b);
        if (!(dt > tiny) || !(ds > tiny) || !std::isfinite(dt)) continue;
        const double ratio = dt / ds;
        if (ratio < o.ratio_low || ratio > o.ratio_high) {
          keep[a][b] = 0;
          ++rep.dropped_channels;
        }
      }
  }
  auto nearest_constraint = [k](const Eigen::MatrixXd& D, Eigen::Index row) {
    int best = 0;
    for (int c = 1; c < k; ++c)
      if (D(row, c) < D(row, best)) best = c;
    return best;
  };

  res.status.assign(nv, TextureVertexStatus::Unmatched);
  res.uv = Eigen::MatrixX2d::Constant(nv, 2, kNaN);
  for (int c = 0; c < k; ++c)
    if (constraints_[c].vertex >= 0) {
      res.status[constraints_[c].vertex] = TextureVertexStatus::Constraint;
      res.uv.row(constraints_[c].vertex) = constraints_[c].pixel.transpose();
    }
  // Group the free vertices by the channel set they use (nearest constraint's keep row).
  const int m_local = o.local_channels > 0 ? std::min(k, std::max(3, o.local_channels)) : k;
  std::map<std::vector<char>, std::vector<long>> groups;
  for (long v = 0; v < nv; ++v) {
    if (res.status[v] == TextureVertexStatus::Constraint) continue;
    if (!FT.row(v).allFinite()) continue;  // another component than some constraint
    std::vector<char> key = keep[nearest_constraint(FT, v)];
    if (m_local < k) {
      // Only the m nearest constraints' channels: local geodesic coordinates are reliable,
      // far ones wrap around closed surfaces differently on the mesh and on the image.
      std::vector<int> order(k);
      std::iota(order.begin(), order.end(), 0);
      std::partial_sort(order.begin(), order.begin() + m_local, order.end(), [&](int a, int b) { return FT(v, a) < FT(v, b); });
      std::vector<char> near(k, 0);
      for (int t = 0; t < m_local; ++t) near[order[t]] = 1;
      for (int c = 0; c < k; ++c) key[c] = key[c] && near[c];
    }
    groups[key].push_back(v);
  }
  // Grid-node channel masks: nodes use the channels of their own nearest constraint.
  std::vector<char> gg_border(gg.active(), 0);
  for (long a = 0; a < gg.active(); ++a) {
    const int i = gg.node_x[a], j = gg.node_y[a];
    gg_border[a] = gg.at(i - 1, j) < 0 || gg.at(i + 1, j) < 0 || gg.at(i, j - 1) < 0 || gg.at(i, j + 1) < 0;
  }
  std::vector<int> node_cell(gg.active());
  for (long a = 0; a < gg.active(); ++a) node_cell[a] = nearest_constraint(FS, a);
  for (const auto& [mask, verts] : groups) {
    std::vector<int> ch;
    for (int c = 0; c < k; ++c)
      if (mask[c]) ch.push_back(c);
    const int kd = static_cast<int>(ch.size());
    if (kd == 0) continue;
    // Nodes whose own channel set disagrees with this one still take part: the dropped channels
    // are simply ignored for this group (a node's mask only matters for its own cell).
    // Candidate nodes: all, or (local channels) those whose nearest constraint is one of the group's.
    std::vector<int> nodes;
    for (long a = 0; a < gg.active(); ++a)
      if (m_local == k || mask[node_cell[a]]) nodes.push_back(static_cast<int>(a));
    if (nodes.empty()) continue;
    KdMatrix P(static_cast<Eigen::Index>(nodes.size()), kd);
    for (std::size_t r = 0; r < nodes.size(); ++r)
      for (int t = 0; t < kd; ++t) P(static_cast<Eigen::Index>(r), t) = FS(nodes[r], ch[t]);
    KdTree tree(kd, std::cref(P), 16);
    const double eps = o.epsilon_factor * diag * k;
    rep.epsilon = eps;
    const double eps_group = o.epsilon_factor * diag * kd;
#pragma omp parallel for schedule(dynamic, 256)
    for (long q = 0; q < static_cast<long>(verts.size()); ++q) {
      const long v = verts[q];
      std::vector<double> f(kd);
      for (int t = 0; t < kd; ++t) f[t] = FT(v, ch[t]);
      Eigen::Index idx = 0;
      double d2 = 0;
      nanoflann::KNNResultSet<double, Eigen::Index> rs(1);
      rs.init(&idx, &d2);
      tree.index->findNeighbors(rs, f.data(), nanoflann::SearchParams());
      if (!(std::sqrt(d2) < eps_group)) continue;
      idx = nodes[idx];
      // Sub-node refinement: Gauss-Newton on the bilinear field around the node.
      double u = gg.node_x[idx], w = gg.node_y[idx];
      const double u0 = u, w0 = w;
      for (int it = 0; it < 4; ++it) {
        int i = std::clamp(static_cast<int>(std::floor(u)), 0, gg.w - 2), j = std::clamp(static_cast<int>(std::floor(w)), 0, gg.h - 2);
        if (!gg.cellActive(i, j)) break;
        const double fu = u - i, fw = w - j;
        const int n00 = gg.at(i, j), n10 = gg.at(i + 1, j), n01 = gg.at(i, j + 1), n11 = gg.at(i + 1, j + 1);
        Eigen::Matrix2d JtJ = Eigen::Matrix2d::Zero();
        Eigen::Vector2d Jtr = Eigen::Vector2d::Zero();
        for (int t = 0; t < kd; ++t) {
          const int c = ch[t];
          const double a00 = FS(n00, c), a10 = FS(n10, c), a01 = FS(n01, c), a11 = FS(n11, c);
          const double val = (1 - fu) * (1 - fw) * a00 + fu * (1 - fw) * a10 + (1 - fu) * fw * a01 + fu * fw * a11;
          const Eigen::Vector2d J((1 - fw) * (a10 - a00) + fw * (a11 - a01), (1 - fu) * (a01 - a00) + fu * (a11 - a10));
          JtJ += J * J.transpose();
          Jtr += J * (f[t] - val);
        }
        JtJ.diagonal().array() += 1e-12 + 1e-6 * JtJ.trace();
        const Eigen::Vector2d delta = JtJ.ldlt().solve(Jtr);
        if (!delta.allFinite()) break;
        u = std::clamp(u + delta.x(), std::max(0.0, u0 - 1), std::min(gg.w - 1.0, u0 + 1));
        w = std::clamp(w + delta.y(), std::max(0.0, w0 - 1), std::min(gg.h - 1.0, w0 + 1));
        if (delta.norm() < 1e-3) break;
      }
      if (o.reject_border_matches) {
        // A vertex beyond the edge of the image (or of a pattern piece) finds its nearest vector
        // on the edge: such matches pile up on the border and fold the UVs there.
        const int nd = gg.at(static_cast<int>(std::lround(u)), static_cast<int>(std::lround(w)));
        if (nd < 0 || gg_border[nd]) continue;
      }
      res.uv(v, 0) = u * gg.sx;
      res.uv(v, 1) = w * gg.sy;
      res.status[v] = TextureVertexStatus::Matched;
    }
  }
  if (rep.epsilon == 0) rep.epsilon = o.epsilon_factor * diag * k;
  for (long v = 0; v < nv; ++v) {
    if (res.status[v] == TextureVertexStatus::Matched) ++rep.matched;
    if (res.status[v] == TextureVertexStatus::Unmatched) ++rep.unmatched;
  }
  rep.matched_fraction = nv > 0 ? 1.0 - static_cast<double>(rep.unmatched) / nv : 0.0;
  rep.t_matching += seconds_since(t0);

  // ---------------------------------------------------------------- deform 2 (eq. 4.3)
  t0 = Clock::now();
  if (o.sigma > 0) {
    NormalEquations ne(g);
    add_thin_plate(g, ne);
    for (int c = 0; c < k; ++c) ne.addRow(cw[c].data(), static_cast<int>(cw[c].size()), o.omega * o.omega, target[c]);
    std::vector<std::pair<int, double>> wts;
    for (long v = 0; v < nv; ++v) {
      if (res.status[v] != TextureVertexStatus::Matched) continue;
      if (!g.weights(res.uv.row(v).transpose(), wts)) continue;
      const Eigen::Vector3d q = V.row(v).transpose() + o.normal_offset * VN.row(v).transpose();
      ne.addRow(wts.data(), static_cast<int>(wts.size()), o.sigma * o.sigma, q);
    }
    SparseCholesky chol;
    res.surface = solve(ne, chol, "deform 2");
  }
  rep.t_deform2 += seconds_since(t0);
  }
  res.surface_faces = g.faces();
  report_progress(o.progress, 0.9, "texture: report");

  // ---------------------------------------------------------------- report
  {
    // Where the constraint's pixel lands on the final surface, its distance to the target, in
    // units of the local size of a pixel there (mean node-edge length / node spacing).
    rep.constraint_residual_px.resize(k);
    for (int c = 0; c < k; ++c) {
      Eigen::RowVector3d p = Eigen::RowVector3d::Zero();
      double len = 0, spacing = 0;
      for (const auto& [n, w] : cw[c]) {
        p += w * res.surface.row(n);
        const int i = g.node_x[n], j = g.node_y[n];
        const int nb[4] = {g.at(i - 1, j), g.at(i + 1, j), g.at(i, j - 1), g.at(i, j + 1)};
        for (int t = 0; t < 4; ++t)
          if (nb[t] >= 0) {
            len += w * (res.surface.row(nb[t]) - res.surface.row(n)).norm();
            spacing += w * (t < 2 ? g.sx : g.sy);
          }
      }
      const double pixel_size = spacing > 0 ? len / spacing : 0;
      const double d = (p - target[c].transpose()).norm();
      rep.constraint_residual_px[c] = pixel_size > 0 ? d / pixel_size : (d > 0 ? std::numeric_limits<double>::infinity() : 0.0);
      rep.max_constraint_residual_px = std::max(rep.max_constraint_residual_px, rep.constraint_residual_px[c]);
    }
  }
  {
    // UV orientation, angle and area distortion over faces with three UVs.
    std::vector<double> signed_uv;
    std::vector<long> faces;
    double a3 = 0, auv = 0;
    for (long f = 0; f < F.rows(); ++f) {
      const int i = F(f, 0), j = F(f, 1), l = F(f, 2);
      if (res.status[i] == TextureVertexStatus::Unmatched || res.status[j] == TextureVertexStatus::Unmatched ||
          res.status[l] == TextureVertexStatus::Unmatched)
        continue;
      const Eigen::Vector2d e1 = res.uv.row(j) - res.uv.row(i), e2 = res.uv.row(l) - res.uv.row(i);
      signed_uv.push_back(0.5 * (e1.x() * e2.y() - e1.y() * e2.x()));
      faces.push_back(f);
      a3 += 0.5 * (V.row(j) - V.row(i)).cross(V.row(l) - V.row(i)).norm();
      auv += std::abs(signed_uv.back());
    }
    rep.uv_faces = static_cast<long>(faces.size());
    long pos = 0, neg = 0;
    for (double s : signed_uv) {
      if (s > 0) ++pos;
      else if (s < 0) ++neg;
    }
    rep.flipped_uv_faces = std::min(pos, neg) + static_cast<long>(signed_uv.size()) - pos - neg;  // minority + zero-area
    const double s2 = auv > 0 ? a3 / auv : 1.0;
    std::vector<double> angle_err, area_err;
    angle_err.reserve(faces.size());
    area_err.reserve(faces.size());
    auto angles3 = [](const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& p2, double* out) {
      const Eigen::Vector3d q[3] = {p0, p1, p2};
      for (int c = 0; c < 3; ++c) {
        const Eigen::Vector3d a = q[(c + 1) % 3] - q[c], b = q[(c + 2) % 3] - q[c];
        out[c] = std::atan2(a.cross(b).norm(), a.dot(b));
      }
    };
    for (std::size_t t = 0; t < faces.size(); ++t) {
      const long f = faces[t];
      const int i = F(f, 0), j = F(f, 1), l = F(f, 2);
      const double A3 = 0.5 * (V.row(j) - V.row(i)).cross(V.row(l) - V.row(i)).norm();
      if (!(A3 > 0) || signed_uv[t] == 0) continue;
      double ang3[3], anguv[3];
      angles3(V.row(i), V.row(j), V.row(l), ang3);
      const Eigen::Vector3d u0(res.uv(i, 0), res.uv(i, 1), 0), u1(res.uv(j, 0), res.uv(j, 1), 0), u2(res.uv(l, 0), res.uv(l, 1), 0);
      angles3(u0, u1, u2, anguv);
      double e = 0;
      for (int c = 0; c < 3; ++c) e += std::abs(ang3[c] - anguv[c]);
      angle_err.push_back(e / 3 * 180.0 / M_PI);
      area_err.push_back(std::abs(std::log(std::abs(signed_uv[t]) * s2 / A3)));
    }
    auto mean = [](const std::vector<double>& x) { return x.empty() ? 0.0 : std::accumulate(x.begin(), x.end(), 0.0) / x.size(); };
    rep.angle_distortion_mean_deg = mean(angle_err);
    rep.angle_distortion_p95_deg = percentile(angle_err, 0.95);
    rep.area_distortion_mean = mean(area_err);
    rep.area_distortion_p95 = percentile(area_err, 0.95);
  }
  if (o.surface_fit_report) {
    // Distortion of the deformed image itself where it lies on the mesh (what Fig. 4.7 shows):
    // grid cells whose three corners are within 1 % of the bbox diagonal of the (offset) mesh.
    const MeshDistance mesh_md(V, F);
    const Eigen::VectorXd d_node = mesh_md.distances(res.surface);
    const Eigen::VectorXd d_vert = MeshDistance(res.surface, res.surface_faces).distances(V);
    const double near = 0.01 * diag + std::abs(o.normal_offset);
    std::vector<double> cell_angle, cell_area;
    for (int j = 0; j + 1 < g.h; ++j)
      for (int i = 0; i + 1 < g.w; ++i) {
        const int a = g.at(i, j), b = g.at(i + 1, j), c = g.at(i, j + 1);
        if (a < 0 || b < 0 || c < 0 || d_node(a) > near || d_node(b) > near || d_node(c) > near) continue;
        const Eigen::Vector3d e1 = res.surface.row(b) - res.surface.row(a), e2 = res.surface.row(c) - res.surface.row(a);
        const double ar = e1.cross(e2).norm();
        if (!(ar > 0)) continue;
        cell_angle.push_back(std::abs(std::atan2(ar, e1.dot(e2)) * 180.0 / M_PI - 90.0));
        cell_area.push_back(ar);
      }
    rep.surface_cells_on_mesh = static_cast<long>(cell_area.size());
    if (!cell_area.empty()) {
      const double med = percentile(cell_area, 0.5);
      double sa = 0, sl = 0;
      for (std::size_t t = 0; t < cell_area.size(); ++t) {
        sa += cell_angle[t];
        sl += std::abs(std::log(cell_area[t] / med));
      }
      rep.surface_angle_distortion_mean_deg = sa / cell_area.size();
      rep.surface_area_distortion_mean = sl / cell_area.size();
    }
    // Only the vertices the image reaches (matched or constraints) count for the fit.
    double sum = 0;
    long n = 0;
    for (long v = 0; v < nv; ++v)
      if (res.status[v] != TextureVertexStatus::Unmatched) {
        const double dv = std::abs(d_vert(v) - std::abs(o.normal_offset));
        sum += dv;
        rep.mesh_to_surface_max = std::max(rep.mesh_to_surface_max, dv);
        ++n;
      }
    rep.mesh_to_surface_mean = n ? sum / n : 0.0;
  }
  rep.roughness = roughness(g, res.surface);
  rep.initial_roughness = roughness(g, res.initial_surface);
  rep.t_total = seconds_since(t_start);
  report_progress(o.progress, 1.0, "texture: done");
  last_report_ = res.report;
  return res;
}

}  // namespace tbsp
