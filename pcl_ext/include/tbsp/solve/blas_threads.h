#pragma once
/// \file blas_threads.h
/// \brief Scoped limit on OpenBLAS's own thread pool.
///
/// CHOLMOD's supernodal factorization calls BLAS; with the pthreads build of OpenBLAS (Debian's
/// default) its worker threads spin while tbsp's OpenMP loops run and the other way round. On
/// the mesh systems of the fitting (tens of thousands of unknowns, small supernodes) the BLAS
/// threads gain little and the contention costs ~8 % of a 43k-vertex fit on 2 cores, so the
/// fitting runs with one BLAS thread. Found at run time (dlsym): without OpenBLAS, or with a
/// BLAS that has no such call, this does nothing. The setting is process-wide: overlapping
/// scopes in several threads (concurrent fits) restore in their own order, so the count after
/// the last one ends may be 1; set it again with openblas_set_num_threads if that matters.
namespace tbsp {

class ScopedBlasThreads {
public:
  /// Sets OpenBLAS to `threads` threads until destruction (then restores the previous count).
  explicit ScopedBlasThreads(int threads);
  ~ScopedBlasThreads();
  ScopedBlasThreads(const ScopedBlasThreads&) = delete;
  ScopedBlasThreads& operator=(const ScopedBlasThreads&) = delete;
  /// True if an OpenBLAS thread control was found and applied.
  bool active() const { return previous_ > 0; }

private:
  int previous_ = 0;
};

}  // namespace tbsp
