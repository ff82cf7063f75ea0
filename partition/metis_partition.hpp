// Partition: which rank owns each molecule. METIS k-way on the connection graph, run once on rank 0 and
// broadcast (fine up to tens of millions of molecules; beyond, see docs/design.md, "Data flow and ranks").
#pragma once
#include <mpi.h>

#include <cstdint>
#include <string>
#include <vector>

#include "src/model/body.hpp"

namespace tissue {

struct PartitionStats {
  long edge_cut = 0;        // connections whose ends sit on different ranks
  double imbalance = 1.0;   // largest part / mean part
  double surface_to_volume = 0.0;  // ghost molecules / owned molecules, largest over ranks (set by the builders)
};

// METIS's allowed imbalance, in thousandths over 1 (its default is 30: 3 %). Every rank computes its molecules'
// connections and the slowest rank sets the step, so the tightest balance pays (docs/benchmarks.md).
constexpr int kMetisImbalance = 1;


// Collective: METIS k-way, with the options above, on the graph that rank 0 alone holds (CSR, both directions of
// every connection, rows sorted; empty elsewhere), freed as soon as METIS returns. Returns the part of every
// molecule on rank 0 (empty elsewhere); stats.edge_cut and stats.imbalance are set on every rank.
std::vector<int> partition_graph_on_rank0(std::vector<int>&& xadj, std::vector<int>&& adjncy, std::int64_t n,
                                          MPI_Comm comm, PartitionStats& stats);

// The same for box lattices whose connections come from the topology stencils: rank 0 builds the graph from the
// stencils (the only place it exists); past 32,768 molecules the graph is of blocks of molecules
// (partition/lattice_blocks.hpp), so rank 0 holds a few bytes a molecule. Returns the parts of this rank's block of the natural order
// (NaturalOrder::block_begin): no rank holds the whole partition.
std::vector<int> partition_lattice(const Body& shape, MPI_Comm comm, PartitionStats& stats);
// The same by partition.method: metis (above) or ptscotch (every rank its block's rows; the edge cut is left
// 0 for the caller to count).
std::vector<int> partition_lattice(const Body& shape, MPI_Comm comm, PartitionStats& stats,
                                   PartitionSpec::Method method);

}  // namespace tissue
