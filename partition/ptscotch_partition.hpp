// partition.method = "ptscotch": PT-Scotch through PETSc's MatPartitioning, run on every rank, each with its own
// block of the connection graph (an MPIAdj matrix), for graphs too large for one rank's memory (METIS runs on
// rank 0 alone). The graph is still read from the global Body here; a slab-wise body would hand over only its
// rows.
#pragma once
#include <mpi.h>

#include <vector>

#include "partition/metis_partition.hpp"

namespace tissue {

// part[m] = the rank that owns molecule m, on every rank; stats: edge cut and imbalance. Collective.
std::vector<int> partition_ptscotch(const Body& body, MPI_Comm comm, PartitionStats& stats);

}  // namespace tissue
