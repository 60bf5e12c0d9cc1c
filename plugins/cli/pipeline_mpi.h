#pragma once
// `tbsp run` under mpirun: frames split over the ranks, outputs gathered and written by rank 0
// (pipeline_mpi.cpp; only in builds with Open MPI).
#include <cstdlib>

#include "tbsp/plugins/pipeline.h"

namespace tbsp::cli {

/// True when the process was started by mpirun/mpiexec (Open MPI, MPICH or PMIx variables).
inline bool launched_by_mpirun() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK"})
    if (std::getenv(v)) return true;
  return false;
}

/// Runs the pipeline as one rank of MPI_COMM_WORLD (MPI_Init .. MPI_Finalize inside); returns the
/// exit code (0, or the failing rank's: 2 invalid input, 3 numerical, 130 cancelled, 1 other).
int run_distributed(const pipeline::Pipeline& p, const pipeline::Registry& reg, pipeline::RunOptions o, bool quiet);

}  // namespace tbsp::cli
