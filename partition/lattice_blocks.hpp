// Box lattices partitioned through a coarse graph: blocks of b x b x b molecules are the vertices (weighted by
// their molecule count), and two blocks are joined by an edge weighted by the number of connections between them.
// METIS's edge cut of the coarse graph is then exactly the molecule graph's cut, and no rank ever builds the
// molecule graph: rank 0 holds about (N / b^3) * 20 edges instead of the fine graph (docs/benchmarks.md).
#pragma once
#include <mpi.h>

#include <cstdint>
#include <vector>

#include "partition/metis_partition.hpp"
#include "src/model/body.hpp"

namespace tissue {

// The block edge for `parts` parts: the smallest b that leaves at most max(32,768, 128 parts) blocks, so rank 0's
// graph stays small and every part still gets many blocks to balance with; b = 1 (the molecule graph itself, as
// the explicit path partitions) for lattices within that count. The block graph's cut is no worse than the
// molecule graph's, in a tenth of the time (docs/benchmarks.md).
int lattice_block_size(const Body& shape, int parts);

// Collective over comm. The parts (0 .. parts - 1) of this rank's block of the natural order
// (NaturalOrder::block_begin over comm's size), from METIS k-way on the coarse graph of `block`-sized blocks.
// parts need not equal comm's size (run_scripts/partition_table partitions for many parts on one rank).
// stats: edge cut (molecule connections between parts) and imbalance (largest part / mean), on every rank.
std::vector<int> partition_lattice_blocks(const Body& shape, MPI_Comm comm, int parts, int block, PartitionStats& stats);

}  // namespace tissue
