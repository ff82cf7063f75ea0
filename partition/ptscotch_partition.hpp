// partition.method = "ptscotch": PT-Scotch through PETSc's MatPartitioning, run on every rank, each handing over
// only its block of rows of the connection graph (an MPIAdj matrix), for graphs too large for one rank's memory
// (METIS runs on rank 0 alone).
#pragma once
#include <mpi.h>

#include <cstdint>
#include <functional>
#include <vector>

#include "partition/metis_partition.hpp"

namespace tissue {

// The owning rank of each molecule of this rank's block [begin, end) of n molecules (the blocks of the ranks in
// order cover 0 .. n-1), given the neighbours of each molecule of the block. Sets stats.imbalance; the edge cut
// needs the neighbours' parts: the caller counts it (partition_ptscotch, or from the LocalModel). Collective.
std::vector<int> ptscotch_block(std::int64_t begin, std::int64_t end, std::int64_t n,
                                const std::function<void(std::int64_t, std::vector<std::int64_t>&)>& neighbours,
                                MPI_Comm comm, PartitionStats& stats);


}  // namespace tissue
