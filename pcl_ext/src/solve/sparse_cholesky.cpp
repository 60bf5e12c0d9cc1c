#include "tbsp/solve/sparse_cholesky.h"

#include "tbsp/solve/blas_threads.h"
#include "supernodal_solve.h"

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <vector>
#ifdef TBSP_HAVE_CHOLMOD
#include <Eigen/CholmodSupport>
#endif

#ifdef _OPENMP
#include <omp.h>
#endif

#include "tbsp/core/error.h"

namespace tbsp {

namespace {
// CHOLMOD (SuiteSparse 5) runs parts of the supernodal factorization in OpenMP regions with a
// compile-time team size (CHOLMOD_OMP_NUM_THREADS = 4) that OMP_NUM_THREADS does not cap. On a
// machine with fewer cores the oversubscribed team spends its time in futex waits and context
// switches: a 43k-unknown factorization takes 0.19 s instead of 0.11 s on 2 cores. With
// dynamic adjustment on, the OpenMP runtime caps every team at the free cores. The loops
// concerned (zeroing, scattering into supernodes) are element-wise: the factor is bit-identical
// whatever the team size. Scoped to the calling thread's ICV; restored afterwards.
class ScopedOmpDynamic {
public:
  ScopedOmpDynamic() {
#ifdef _OPENMP
    previous_ = omp_get_dynamic();
    if (!previous_) omp_set_dynamic(1);
#endif
  }
  ~ScopedOmpDynamic() {
#ifdef _OPENMP
    if (!previous_) omp_set_dynamic(0);
#endif
  }
  ScopedOmpDynamic(const ScopedOmpDynamic&) = delete;
  ScopedOmpDynamic& operator=(const ScopedOmpDynamic&) = delete;

private:
  int previous_ = 1;
};
}  // namespace

#ifdef TBSP_HAVE_CHOLMOD
namespace {
// Eigen keeps the CHOLMOD factor protected; the solve below reads it directly.
class CholmodLLT : public Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>> {
public:
  const cholmod_factor* factor() const { return m_cholmodFactor; }
  /// Takes a copy of `from`'s factor (symbolic or numeric) as this solver's analysis, as
  /// analyzePattern() leaves it: the next factorize() refactorizes it in place.
  bool copyAnalysis(const CholmodLLT& from) {
    if (!from.m_cholmodFactor || !from.m_analysisIsOk) return false;
    cholmod_factor* copy = cholmod_copy_factor(from.m_cholmodFactor, &cholmod());
    if (!copy) return false;  // out of memory: the next compute() analyses as usual
    if (m_cholmodFactor) cholmod_free_factor(&m_cholmodFactor, &cholmod());
    m_cholmodFactor = copy;
    this->m_isInitialized = true;
    this->m_info = Eigen::Success;
    m_analysisIsOk = true;
    m_factorizationIsOk = false;
    return true;
  }
};

// The view of a supernodal LLᵀ factor with int indices and real values, or an empty one
// (n = 0) for any other kind (then CHOLMOD's own solve runs).
detail::SupernodalFactorView supernodal_view(const cholmod_factor* f) {
  detail::SupernodalFactorView v;
  if (!f || !f->is_super || !f->is_ll || f->itype != CHOLMOD_INT || f->xtype != CHOLMOD_REAL ||
      f->dtype != CHOLMOD_DOUBLE || !f->x || !f->Perm)
    return v;
  v.n = int(f->n);
  v.nsuper = int(f->nsuper);
  v.perm = static_cast<const int*>(f->Perm);
  v.super = static_cast<const int*>(f->super);
  v.pi = static_cast<const int*>(f->pi);
  v.px = static_cast<const int*>(f->px);
  v.s = static_cast<const int*>(f->s);
  v.x = static_cast<const double*>(f->x);
  for (int k = 0; k < v.nsuper; ++k) v.max_rows = std::max(v.max_rows, v.pi[k + 1] - v.pi[k]);
  return v;
}
}  // namespace
#endif

struct SparseCholesky::Impl {
  Backend backend = Backend::EigenLDLT;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;
#ifdef TBSP_HAVE_CHOLMOD
  CholmodLLT cholmod;
  detail::SupernodalFactorView view;  // of cholmod's factor after the last factorization
  detail::SupernodalPlan plan;        // its two-part split (rebuilt with each analysis)
#endif
  bool factorized = false;
  bool cholmod_solve = false;
  Eigen::Index n = 0;
  std::vector<int> outer, inner;  // pattern of the last analysed matrix
  bool analysed = false;          // an analysis of that pattern is held (own or copied)
  int analyses = 0, factorizations = 0;
};

SparseCholesky::SparseCholesky(Backend backend) : impl_(std::make_unique<Impl>()) {
#ifdef TBSP_HAVE_CHOLMOD
  impl_->backend = backend == Backend::EigenLDLT ? Backend::EigenLDLT : Backend::Cholmod;
#else
  if (backend == Backend::Cholmod)
    throw InvalidInput("[tbsp::SparseCholesky] CHOLMOD was requested but tbsp was built without it "
                       "(reconfigure with -DTBSP_WITH_CHOLMOD=ON and libsuitesparse-dev installed)");
  impl_->backend = Backend::EigenLDLT;
#endif
}
SparseCholesky::~SparseCholesky() = default;
SparseCholesky::SparseCholesky(SparseCholesky&&) noexcept = default;
SparseCholesky& SparseCholesky::operator=(SparseCholesky&&) noexcept = default;

bool SparseCholesky::cholmodAvailable() {
#ifdef TBSP_HAVE_CHOLMOD
  return true;
#else
  return false;
#endif
}

void SparseCholesky::compute(const Eigen::SparseMatrix<double>& A_in) {
  if (A_in.rows() != A_in.cols())
    throw InvalidInput("[tbsp::SparseCholesky::compute] matrix is " + std::to_string(A_in.rows()) + "x" +
                       std::to_string(A_in.cols()) + ", expected square");
  // CHOLMOD needs a compressed matrix: copy only when the caller's is not
  Eigen::SparseMatrix<double> copy;
  if (!A_in.isCompressed()) {
    copy = A_in;
    copy.makeCompressed();
  }
  const Eigen::SparseMatrix<double>& A = A_in.isCompressed() ? A_in : copy;
  const ScopedOmpDynamic omp_dynamic;
  // one BLAS thread: OpenBLAS splits its GEMM work differently with 1, 2 or 4 threads and the
  // factor's last bits follow (tests saw 4e-15 between OMP_NUM_THREADS=1 and 2); results must
  // not depend on the thread count. Our callers parallelise per element instead.
  const ScopedBlasThreads blas_threads(1);
  Impl& m = *impl_;
  m.factorized = false;
  const bool same_pattern =
      m.analysed && m.n == A.rows() && m.outer.size() == std::size_t(A.outerSize() + 1) &&
      std::equal(m.outer.begin(), m.outer.end(), A.outerIndexPtr()) && m.inner.size() == std::size_t(A.nonZeros()) &&
      std::equal(m.inner.begin(), m.inner.end(), A.innerIndexPtr());
  bool ok = false;
#ifdef TBSP_HAVE_CHOLMOD
  if (m.backend == Backend::Cholmod) {
    if (!same_pattern) { m.cholmod.analyzePattern(A); ++m.analyses; }
    m.cholmod.factorize(A);
    ok = m.cholmod.info() == Eigen::Success;
    m.view = ok ? supernodal_view(m.cholmod.factor()) : detail::SupernodalFactorView{};
    if (m.view.n > 0 && (!same_pattern || m.plan.top_index.size() != std::size_t(m.view.n)))
      m.plan = detail::make_supernodal_plan(m.view);
  }
#endif
  if (m.backend == Backend::EigenLDLT) {
    if (!same_pattern) { m.ldlt.analyzePattern(A); ++m.analyses; }
    m.ldlt.factorize(A);
    ok = m.ldlt.info() == Eigen::Success && (m.ldlt.vectorD().array() > 0).all();
  }
  if (!same_pattern) {
    m.outer.assign(A.outerIndexPtr(), A.outerIndexPtr() + A.outerSize() + 1);
    m.inner.assign(A.innerIndexPtr(), A.innerIndexPtr() + A.nonZeros());
  }
  m.analysed = true;
  m.n = A.rows();
  ++m.factorizations;
  if (!ok)
    throw NumericalFailure("[tbsp::SparseCholesky::compute] the " + std::to_string(A.rows()) + "x" +
                           std::to_string(A.rows()) + " system is not positive definite (" + backendName() +
                           "): the problem is under-constrained; add constraints so every part is pinned down");
  m.factorized = true;
}

void SparseCholesky::copyAnalysis(const SparseCholesky& other) {
  const Impl& o = *other.impl_;
  Impl& m = *impl_;
  // (SimplicialLDLT's analysis cannot be copied: the next compute() analyses anew)
  if (this == &other || !o.analysed || o.backend != m.backend || m.backend != Backend::Cholmod) return;
#ifdef TBSP_HAVE_CHOLMOD
  if (!m.cholmod.copyAnalysis(o.cholmod)) return;
  m.view = detail::SupernodalFactorView{};
  m.plan = detail::SupernodalPlan{};
  m.factorized = false;
  m.outer = o.outer;
  m.inner = o.inner;
  m.n = o.n;
  m.analysed = true;
#endif
}

Eigen::MatrixXd SparseCholesky::solve(const Eigen::MatrixXd& B) const {
  Eigen::MatrixXd X;
  solve(B, X);
  return X;
}

void SparseCholesky::solve(const Eigen::MatrixXd& B, Eigen::MatrixXd& X) const {
  const Impl& m = *impl_;
  if (!m.factorized) throw NumericalFailure("[tbsp::SparseCholesky::solve] no factorization; call compute() first");
  if (B.rows() != m.n)
    throw InvalidInput("[tbsp::SparseCholesky::solve] right-hand side has " + std::to_string(B.rows()) +
                       " rows, the system " + std::to_string(m.n));
  bool done = false;
#ifdef TBSP_HAVE_CHOLMOD
  if (m.backend == Backend::Cholmod && !m.cholmod_solve && m.view.n == m.n && B.cols() > 0) {
    // one buffer per thread, grown, never shrunk: no allocation once warm
    thread_local std::vector<double> work;
    const std::size_t need = detail::supernodal_work_size(m.view, m.plan, int(B.cols()));
    if (work.size() < need) work.resize(need);
    if (X.rows() != B.rows() || X.cols() != B.cols()) X.resize(B.rows(), B.cols());
    detail::supernodal_solve(m.view, m.plan, int(B.cols()), B.data(), B.rows(), X.data(), X.rows(), work.data(),
                             true);
    done = true;
  }
#endif
  if (!done) {
    const ScopedOmpDynamic omp_dynamic;
    const ScopedBlasThreads blas_threads(1);  // (see compute)
#ifdef TBSP_HAVE_CHOLMOD
    if (m.backend == Backend::Cholmod) X = m.cholmod.solve(B);
#endif
    if (m.backend == Backend::EigenLDLT) X = m.ldlt.solve(B);
  }
  if (!X.allFinite()) throw NumericalFailure("[tbsp::SparseCholesky::solve] the solution is not finite");
}

void SparseCholesky::setCholmodSolve(bool on) { impl_->cholmod_solve = on; }

std::size_t SparseCholesky::factorNonZeros() const {
  const Impl& m = *impl_;
  if (!m.factorized) return 0;
#ifdef TBSP_HAVE_CHOLMOD
  if (m.backend == Backend::Cholmod) return m.view.values();
#endif
  return std::size_t(m.ldlt.matrixL().nestedExpression().nonZeros()) + std::size_t(m.n);
}

bool SparseCholesky::isFactorized() const { return impl_->factorized; }
Eigen::Index SparseCholesky::rows() const { return impl_->n; }
std::string SparseCholesky::backendName() const {
  return impl_->backend == Backend::Cholmod ? "cholmod-supernodal" : "eigen-simplicial-ldlt";
}
int SparseCholesky::numAnalyses() const { return impl_->analyses; }
int SparseCholesky::numFactorizations() const { return impl_->factorizations; }

}  // namespace tbsp
