// LaplacianDeformer's rotation field (§3.2.3): the constraint graph over handles and vertices,
// node rotations, harmonic interpolation, rotated differential coordinates (eq. 3.12).
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <limits>
#include <map>
#include <set>
#include <string>

#include "laplacian_deformer_cache.h"
#include "tbsp/core/error.h"
#include "tbsp/core/progress.h"
#include "tbsp/core/timer.h"
#include "tbsp/deform/rotations.h"

namespace tbsp {

void LaplacianDeformer::buildRotationGraph(bool with_progress) {
  Cache& c = *cache_;
  if (!user_rotations_.empty() || !use_rotation_field_ || c.graph_valid) return;
  const auto t0 = Clock::now();
  // graph nodes: one per handle group (its representative vertex: the one nearest the group's
  // rest centroid), one per other constrained vertex; the rotation field is pinned at every
  // constrained vertex, each to its node's rotation. The geodesic searches and the O(k²) graph
  // grow with the number of nodes, not with the size of the handle regions.
  std::map<int, std::vector<int>> by_group, by_vertex;
  auto vertex_of = [&](const DeformConstraint& con) {
    int v = con.at.vertex;
    if (v < 0) {
      int k;
      con.at.bary.maxCoeff(&k);
      v = mesh_.F(con.at.face, k);
    }
    return v;
  };
  std::map<int, int> group_of_vertex;  // a vertex in several groups belongs to the first
  for (std::size_t id = 0; id < constraints_.size(); ++id) {
    const auto& con = constraints_[id];
    if (con.type != ConstraintType::Position || con.group < 0) continue;
    by_group[con.group].push_back(int(id));
    group_of_vertex.emplace(vertex_of(con), con.group);
  }
  for (std::size_t id = 0; id < constraints_.size(); ++id) {
    const auto& con = constraints_[id];
    if (con.type != ConstraintType::Position || con.group >= 0) continue;
    const int v = vertex_of(con);
    auto g = group_of_vertex.find(v);
    if (g != group_of_vertex.end()) by_group[g->second].push_back(int(id));  // inside a handle region
    else by_vertex[v].push_back(int(id));
  }
  std::vector<int> nodes;
  std::set<int> used;
  std::map<int, int> field_index;  // vertex -> index in field_vertices
  c.node_constraints.clear();
  c.node_is_group.clear();
  c.field_vertices.clear();
  c.field_node.clear();
  auto pin = [&](int v, int node) {
    if (field_index.emplace(v, int(c.field_vertices.size())).second) {
      c.field_vertices.push_back(v);
      c.field_node.push_back(node);
    }
  };
  for (auto& [g, ids] : by_group) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int id : ids) centroid += evaluate(constraints_[std::size_t(id)].at, mesh_.V);
    centroid /= double(ids.size());
    int rep = -1;
    double best = std::numeric_limits<double>::infinity();
    for (int id : ids) {
      const int v = vertex_of(constraints_[std::size_t(id)]);
      if (used.count(v)) continue;  // (two groups sharing vertices: distinct representatives)
      const double d = (mesh_.V.row(v).transpose() - centroid).squaredNorm();
      if (d < best || (d == best && v < rep)) { best = d; rep = v; }
    }
    if (rep < 0) continue;  // every vertex of this group is already another group's: it joins that one
    used.insert(rep);
    nodes.push_back(rep);
    c.node_constraints.push_back(ids);
    c.node_is_group.push_back(1);
  }
  for (auto& [v, ids] : by_vertex) {
    nodes.push_back(v);
    c.node_constraints.push_back(ids);
    c.node_is_group.push_back(0);
  }
  if (nodes.empty())
    throw InvalidInput("[tbsp::LaplacianDeformer::deform] the rotation field needs position constraints (none set)");
  // representatives first (their graph order), then the other vertices of each group
  for (std::size_t i = 0; i < nodes.size(); ++i) pin(nodes[i], int(i));
  for (std::size_t i = 0; i < nodes.size(); ++i)
    for (int id : c.node_constraints[i]) pin(vertex_of(constraints_[std::size_t(id)]), int(i));
  ProgressCallback sub;
  if (progress_ && with_progress) sub = [this](double f, const std::string& s) { return progress_(0.05 + 0.2 * f, s); };
  c.graph = ConstraintGraph::build(mesh_.V, mesh_.F, nodes, 3, sub);
  // hemisphere consistency over the field vertices: the graph's tree over the representatives,
  // each other group vertex a child of its representative (same rotation, same sign)
  std::vector<int> parent(c.field_vertices.size(), -1), order;
  for (int i : c.graph.tree_order) order.push_back(i);
  for (std::size_t i = 0; i < nodes.size(); ++i) parent[i] = c.graph.tree_parent[i];
  for (std::size_t f = nodes.size(); f < c.field_vertices.size(); ++f) {
    parent[f] = c.field_node[f];
    order.push_back(int(f));
  }
  c.field.compute(c.C, mesh_.F, c.field_vertices, parent, order);  // the matrix setMesh built
  c.graph_valid = true;
  report_.t_graph = seconds_since(t0);
}

Eigen::MatrixX3d LaplacianDeformer::rotatedDelta() {
  Cache& c = *cache_;
  last_rotations_.clear();
  report_.rotation_field = false;
  report_.rotation_nodes = 0;
  if (!user_rotations_.empty()) {
    last_rotations_ = user_rotations_;
  } else if (use_rotation_field_) {
    buildRotationGraph(true);
    const auto t1 = Clock::now();
    report_progress(progress_, 0.3, "rotations");
    const std::size_t k = c.graph.nodes.size();
    Eigen::MatrixX3d P(Eigen::Index(k), 3), Q(Eigen::Index(k), 3);
    std::vector<char> given(k, 0);
    std::vector<Eigen::Matrix3d> Rgiven(k);
    for (std::size_t i = 0; i < k; ++i) {
      Eigen::Vector3d p = Eigen::Vector3d::Zero(), q = Eigen::Vector3d::Zero();
      for (int id : c.node_constraints[i]) {
        const auto& con = constraints_[std::size_t(id)];
        p += evaluate(con.at, mesh_.V);
        q += con.target;
        if (con.rotation && !given[i]) { given[i] = 1; Rgiven[i] = *con.rotation; }
      }
      P.row(Eigen::Index(i)) = p.transpose() / double(c.node_constraints[i].size());
      Q.row(Eigen::Index(i)) = q.transpose() / double(c.node_constraints[i].size());
    }
    // a handle region without a given rotation: its own best rigid fit (Procrustes of the
    // centred rest positions to the centred targets), when the region spans more than a line
    std::vector<char> own(k, 0);
    std::vector<Eigen::Matrix3d> Rown(k);
    for (std::size_t i = 0; i < k; ++i) {
      if (given[i] || !c.node_is_group[i] || c.node_constraints[i].size() < 3) continue;
      Eigen::Matrix3d H = Eigen::Matrix3d::Zero(), S = Eigen::Matrix3d::Zero();
      for (int id : c.node_constraints[i]) {
        const auto& con = constraints_[std::size_t(id)];
        const Eigen::Vector3d e = evaluate(con.at, mesh_.V) - P.row(Eigen::Index(i)).transpose();
        const Eigen::Vector3d e2 = con.target - Q.row(Eigen::Index(i)).transpose();
        H += e2 * e.transpose();
        S += e * e.transpose();
      }
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(S);
      if (es.eigenvalues()(1) > 1e-9 * std::max(es.eigenvalues()(2), 1e-300)) {
        own[i] = 1;
        Rown[i] = closest_rotation(H);
      }
    }
    bool need_estimate = false;
    for (std::size_t i = 0; i < k; ++i) need_estimate = need_estimate || (!given[i] && !own[i]);
    if (need_estimate) {
      // the estimate from the graph (eq. 3.13) needs a 3D-ish configuration: at least 3 nodes
      // not on one line
      bool ok = k >= 3;
      if (ok) {
        const Eigen::RowVector3d mean = P.colwise().mean();
        Eigen::MatrixX3d Pc = P.rowwise() - mean;
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(Pc);
        ok = svd.singularValues()(1) > 1e-9 * std::max(1e-300, svd.singularValues()(0));
      }
      if (!ok)
        throw InvalidInput("[tbsp::LaplacianDeformer::deform] the rotation field needs at least 3 position constraints "
                           "not all on one line (got " + std::to_string(k) + " node(s)); add constraints or give "
                           "rotations explicitly");
    }
    std::vector<Eigen::Matrix3d> R = need_estimate ? node_rotations(c.graph, P, Q) : Rgiven;
    for (std::size_t i = 0; i < k; ++i) {
      if (given[i]) R[i] = Rgiven[i];
      else if (own[i]) R[i] = Rown[i];
    }
    std::vector<Eigen::Matrix3d> Rf(c.field_vertices.size());
    for (std::size_t f = 0; f < Rf.size(); ++f) Rf[f] = R[std::size_t(c.field_node[f])];
    last_rotations_ = c.field.interpolate(Rf);
    report_.rotation_field = true;
    report_.rotation_nodes = int(k);
    report_.t_rotations = seconds_since(t1);
  }
  Eigen::MatrixX3d d = scale_ * delta_;
  if (!last_rotations_.empty())
    for (Eigen::Index i = 0; i < d.rows(); ++i) d.row(i) = (last_rotations_[std::size_t(i)] * d.row(i).transpose()).transpose();
  return d;
}

}  // namespace tbsp
