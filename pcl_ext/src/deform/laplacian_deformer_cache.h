#pragma once
// Internal: the LaplacianDeformer's cached system and rotation-field state, shared by
// laplacian_deformer.cpp (system, solve) and laplacian_deformer_rotations.cpp (rotation field).
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <vector>

#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/deform/rotation_field.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp {

namespace detail {
// One scalar equation  m · (Σ_k b_k x_k) = r  with weight w.
struct ScalarRow {
  int cid = 0;
  std::vector<std::pair<int, double>> stencil;  // (vertex, coefficient)
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
};
}  // namespace detail

struct LaplacianDeformer::Cache {
  // system
  bool matrix_valid = false;
  bool coupled = false;
  std::vector<int> free_index;  // vertex -> free row, -1 = fixed
  Eigen::Index n_free = 0;
  Eigen::MatrixX3d X0;          // fixed positions (hard targets / isolated rest), 0 elsewhere
  Eigen::SparseMatrix<double> L_free;  // L̂ restricted to free columns (#V by n_free)
  Eigen::SparseMatrix<double> NL;      // L_freeᵀ L_free, cached while the free set is unchanged
  Eigen::SparseMatrix<double> N_work;  // the fast path's normal matrix (NL's pattern), reused
  std::vector<double> add_work;        // its constraint terms
  std::vector<int> nl_free_index;      // free set NL was built for (empty = invalid)
  std::vector<detail::ScalarRow> rows;  // coupled: every scalar row; uncoupled: one row per position constraint
  double anchor = 0;            // ε of the anchor term
  SparseCholesky solver;
  // re-solve: the right-hand side's part that does not depend on soft targets,
  // L_freeᵀ (δ' − L X0) + ε V, kept while δ' (rotated, scaled δ) and X0 are unchanged
  bool rhs_base_valid = false;
  Eigen::MatrixX3d rhs_delta, rhs_X0;
  Eigen::MatrixXd rhs_base, rhs_work, x_work;
  // components
  Eigen::VectorXi component;
  int num_components = 0;
  std::vector<char> isolated;
  // rotation field
  bool graph_valid = false;
  Eigen::SparseMatrix<double> C;  // the mesh's symmetric matrix L̂ is scaled from (laplacian()'s `stiffness`)
  ConstraintGraph graph;
  RotationField field;
  std::vector<std::vector<int>> node_constraints;  // per graph node, constraint ids
  std::vector<char> node_is_group;                  // per graph node: a handle group
  std::vector<int> field_vertices;                  // Dirichlet vertices of the rotation field
  std::vector<int> field_node;                      // per field vertex, its graph node
};

}  // namespace tbsp
