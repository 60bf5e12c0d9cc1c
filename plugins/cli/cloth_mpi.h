#pragma once
// `tbsp cloth estimate` under mpirun: the estimation's simulations shared over the ranks
// (ClothWorkShare; cloth_mpi.cpp, only in builds with Open MPI).
#include <exception>
#include <string>
#include <vector>

#include "tbsp/cloth/cloth_parameter_estimation.h"

namespace tbsp::cli {

/// Membership of MPI_COMM_WORLD for the object's lifetime (MPI_Init_thread, funneled: only the
/// main thread talks to MPI; MPI_Finalize in the destructor).
class ClothRanks {
public:
  ClothRanks();
  ~ClothRanks();
  ClothRanks(const ClothRanks&) = delete;
  ClothRanks& operator=(const ClothRanks&) = delete;
  int rank() const { return rank_; }
  int size() const { return size_; }
  /// Ranks on this node (MPI_Comm_split_type, shared memory).
  int localSize() const { return local_size_; }
  /// Unless OMP_NUM_THREADS is set: this rank's OpenMP threads = the node's cores / its ranks
  /// (mpirun starts every rank with all cores; 2 ranks × 2 threads on 2 cores only contend).
  void shareCores() const;
  /// The work share over the ranks: the sum is MPI_Allreduce(MPI_SUM) on MPI_COMM_WORLD.
  ClothWorkShare share() const;
  /// Collective: returns when no rank has an error; otherwise every rank throws the error of the
  /// lowest failing rank (its type — invalid input, numerical, cancelled, other — and message).
  /// Used after the steps each rank runs on its own (reading the inputs), so that a rank that
  /// failed alone does not leave the others waiting in the estimation's exchanges.
  void agree(const std::exception_ptr& local) const;
  /// Collective: every rank's bytes, in rank order, on every rank (MPI_Allgatherv).
  /// \throws InvalidInput when the bytes of all ranks exceed one MPI message (2 GB).
  std::vector<std::string> allgather(const std::string& mine) const;

private:
  int rank_ = 0, size_ = 1, local_size_ = 1;
};

}  // namespace tbsp::cli
