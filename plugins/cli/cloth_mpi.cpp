// `tbsp cloth estimate` under mpirun (docs/cloth.md, "Several processes"): every rank runs the
// same estimation and computes its share of the simulations; the ranks' results are summed with
// MPI_Allreduce. Built only with Open MPI (TBSP_WITH_MPI).
// the C API only (Open MPI / MPICH would otherwise pull in their deprecated C++ bindings)
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>

#include <algorithm>
#include <climits>
#include <cstdlib>
#include <string>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "cloth_mpi.h"
#include "tbsp/core/error.h"
#include "tbsp/core/error_kind.h"

namespace tbsp::cli {
namespace {

void all_sum(std::vector<double>& v) {
  if (!v.empty()) MPI_Allreduce(MPI_IN_PLACE, v.data(), int(v.size()), MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
}

}  // namespace

ClothRanks::ClothRanks() {
  int provided = 0;
  MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
  MPI_Comm node;
  MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, rank_, MPI_INFO_NULL, &node);
  MPI_Comm_size(node, &local_size_);
  MPI_Comm_free(&node);
}

void ClothRanks::shareCores() const {
#ifdef _OPENMP
  if (!std::getenv("OMP_NUM_THREADS")) omp_set_num_threads(std::max(1, omp_get_num_procs() / std::max(1, local_size_)));
#endif
}

ClothRanks::~ClothRanks() { MPI_Finalize(); }

ClothWorkShare ClothRanks::share() const {
  ClothWorkShare s;
  s.rank = rank_;
  s.size = size_;
  s.sum = all_sum;
  return s;
}

void ClothRanks::agree(const std::exception_ptr& local) const {
  // per rank: its error kind (0 = none)
  std::vector<double> kinds(std::size_t(size_), 0.0);
  kinds[std::size_t(rank_)] = error_kind(local);
  all_sum(kinds);
  int failed = -1;
  for (int r = 0; r < size_ && failed < 0; ++r)
    if (kinds[std::size_t(r)] != 0) failed = r;
  if (failed < 0) return;
  // the failing rank's error and message, on every rank
  const std::string where = failed != 0 ? "(rank " + std::to_string(failed) + " of " + std::to_string(size_) + ") " : "";
  std::rethrow_exception(share_error(int(kinds[std::size_t(failed)]), failed == rank_, local, all_sum, where));
}

std::vector<std::string> ClothRanks::allgather(const std::string& mine) const {
  // sizes first (as doubles through the sum: exact below 2^53), then the bytes
  std::vector<double> sizes(std::size_t(size_), 0.0);
  sizes[std::size_t(rank_)] = double(mine.size());
  all_sum(sizes);
  double total = 0;
  for (double b : sizes) total += b;
  if (total > double(INT_MAX))  // (the same sizes on every rank: every rank throws)
    throw InvalidInput("the observations of all ranks (" + std::to_string(total / 1e9) +
                       " GB) exceed one MPI message (2 GB): estimate from fewer frames or views per run");
  const std::size_t n = static_cast<std::size_t>(size_);
  std::vector<int> counts(n), displs(n);
  int at = 0;
  for (std::size_t r = 0; r < n; ++r) {
    displs[r] = at;
    counts[r] = int(sizes[r]);
    at += counts[r];
  }
  std::string all(std::size_t(total), '\0');
  MPI_Allgatherv(mine.data(), int(mine.size()), MPI_CHAR, all.data(), counts.data(), displs.data(), MPI_CHAR, MPI_COMM_WORLD);
  std::vector<std::string> out;
  for (int r = 0; r < size_; ++r) out.push_back(all.substr(std::size_t(displs[std::size_t(r)]), std::size_t(counts[std::size_t(r)])));
  return out;
}

}  // namespace tbsp::cli
