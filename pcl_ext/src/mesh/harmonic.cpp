#include "tbsp/mesh/harmonic.h"

#include <string>

#include "tbsp/core/error.h"
#include "tbsp/mesh/topology.h"

namespace tbsp {

void HarmonicInterpolator::compute(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                   const std::vector<int>& constrained, LaplacianWeights weights) {
  compute(laplacian_stiffness(V, F, weights), F, constrained);
}

void HarmonicInterpolator::compute(const Eigen::SparseMatrix<double>& C, const Eigen::MatrixX3i& F,
                                   const std::vector<int>& constrained) {
  const std::string who = "[tbsp::HarmonicInterpolator::compute] ";
  const Eigen::Index n = C.rows();
  if (C.cols() != n)
    throw InvalidInput(who + "the matrix is " + std::to_string(C.rows()) + " by " + std::to_string(C.cols()) +
                       "; it must be square (#V by #V)");
  if (F.size() > 0 && (F.minCoeff() < 0 || F.maxCoeff() >= n))
    throw InvalidInput(who + "the faces index vertices 0.." + std::to_string(F.maxCoeff()) + " but the matrix has " +
                       std::to_string(n) + " rows; pass the matrix of this mesh");
  if (constrained.empty()) throw InvalidInput(who + "no constrained vertices; give at least one value");
  std::vector<char> is_c(std::size_t(n), 0);
  for (int c : constrained) {
    if (c < 0 || c >= n)
      throw InvalidInput(who + "constrained vertex " + std::to_string(c) + " is out of range (mesh has " +
                         std::to_string(n) + " vertices)");
    if (is_c[std::size_t(c)]) throw InvalidInput(who + "vertex " + std::to_string(c) + " is constrained twice");
    is_c[std::size_t(c)] = 1;
  }
  // every face-connected component needs a constrained vertex
  Eigen::VectorXi comp;
  const int k = connected_components(F, n, comp);
  std::vector<char> comp_has(std::size_t(k), 0), comp_has_face(std::size_t(k), 0);
  for (int c : constrained) comp_has[std::size_t(comp(c))] = 1;
  for (Eigen::Index f = 0; f < F.rows(); ++f) comp_has_face[std::size_t(comp(F(f, 0)))] = 1;
  for (Eigen::Index i = 0; i < n; ++i)
    if (comp_has_face[std::size_t(comp(i))] && !comp_has[std::size_t(comp(i))])
      throw InvalidInput(who + "the mesh component containing vertex " + std::to_string(i) +
                         " has no constrained vertex, so its values are undefined; constrain a vertex there or "
                         "remove the component");
  const Eigen::SparseMatrix<double>& K = C;  // the system is −C (SPD on the free vertices)
  free_index_.assign(std::size_t(n), -1);
  std::vector<int> c_index(std::size_t(n), -1);
  int nf = 0;
  for (Eigen::Index i = 0; i < n; ++i)
    if (!is_c[std::size_t(i)] && comp_has_face[std::size_t(comp(i))]) free_index_[std::size_t(i)] = nf++;
  for (std::size_t j = 0; j < constrained.size(); ++j) c_index[std::size_t(constrained[j])] = int(j);
  std::vector<Eigen::Triplet<double>> tff, tfb;
  for (int col = 0; col < K.outerSize(); ++col)
    for (Eigen::SparseMatrix<double>::InnerIterator it(K, col); it; ++it) {
      const int r = free_index_[std::size_t(it.row())];
      if (r < 0) continue;
      const int cf = free_index_[std::size_t(it.col())];
      if (cf >= 0) tff.emplace_back(r, cf, -it.value());
      else if (c_index[std::size_t(it.col())] >= 0) tfb.emplace_back(r, c_index[std::size_t(it.col())], -it.value());
    }
  Eigen::SparseMatrix<double> Kff(nf, nf);
  Kff.setFromTriplets(tff.begin(), tff.end());
  K_fb_.resize(nf, Eigen::Index(constrained.size()));
  K_fb_.setFromTriplets(tfb.begin(), tfb.end());
  has_free_ = nf > 0;
  if (has_free_) solver_.compute(Kff);
  n_ = n;
  constrained_ = constrained;
}

Eigen::MatrixXd HarmonicInterpolator::interpolate(const Eigen::MatrixXd& values) const {
  if (values.rows() != Eigen::Index(constrained_.size()))
    throw InvalidInput("[tbsp::HarmonicInterpolator::interpolate] got " + std::to_string(values.rows()) +
                       " value rows for " + std::to_string(constrained_.size()) + " constrained vertices");
  if (!values.allFinite()) throw InvalidInput("[tbsp::HarmonicInterpolator::interpolate] values contain NaN/Inf");
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(n_, values.cols());
  if (has_free_) {
    const Eigen::MatrixXd xf = solver_.solve(-(K_fb_ * values));
    for (Eigen::Index i = 0; i < n_; ++i)
      if (free_index_[std::size_t(i)] >= 0) out.row(i) = xf.row(free_index_[std::size_t(i)]);
  }
  for (std::size_t j = 0; j < constrained_.size(); ++j) out.row(constrained_[j]) = values.row(Eigen::Index(j));
  return out;
}

Eigen::MatrixXd harmonic_interpolation(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                       const std::vector<int>& constrained, const Eigen::MatrixXd& values,
                                       LaplacianWeights weights) {
  HarmonicInterpolator h;
  h.compute(V, F, constrained, weights);
  return h.interpolate(values);
}

}  // namespace tbsp
