#include "partition/metis_partition.hpp"

#include <metis.h>

#include "partition/agreement.hpp"
#include "partition/box_bisection.hpp"
#include "partition/lattice_blocks.hpp"
#include "partition/natural_order.hpp"
#include "src/model/topology.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "partition/ptscotch_partition.hpp"

namespace tissue {

namespace {

// METIS k-way on a CSR graph (both directions of every connection), on the calling rank. Seeded: the same
// partition every run.
std::vector<idx_t> run_metis(std::vector<idx_t>& xadj, std::vector<idx_t>& adjncy, int parts, long& edge_cut,
                             int& status) {
  idx_t nvtxs = static_cast<idx_t>(xadj.size() - 1), ncon = 1, nparts = parts, objval = 0;
  idx_t options[METIS_NOPTIONS];
  METIS_SetDefaultOptions(options);
  options[METIS_OPTION_SEED] = 1;
  options[METIS_OPTION_UFACTOR] = kMetisImbalance;
  std::vector<idx_t> p(nvtxs);
  status = METIS_PartGraphKway(&nvtxs, &ncon, xadj.data(), adjncy.data(), nullptr, nullptr, nullptr, &nparts,
                               nullptr, nullptr, options, &objval, p.data());
  edge_cut = objval;
  return p;
}

void check_status(int status) {
  if (status != METIS_OK) throw std::runtime_error("METIS_PartGraphKway failed with status " + std::to_string(status));
}

}  // namespace

std::vector<int> partition_graph_on_rank0(std::vector<int>&& xadj, std::vector<int>&& adjncy, std::int64_t n,
                                          MPI_Comm comm, PartitionStats& stats) {
  static_assert(std::is_same_v<idx_t, int>, "METIS built with 32-bit indices");
  int rank, size;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  stats = PartitionStats{};
  std::vector<int> part;
  // Rank 0 partitions alone: agreed (partition/agreement.hpp), so that its failure (METIS, memory) stops every
  // rank here instead of leaving them in the broadcasts below.
  agree(comm, [&] {
    if (rank != 0) return;
    fault_point("partition", comm);
    int status = METIS_OK;
    std::vector<idx_t> p = run_metis(xadj, adjncy, size, stats.edge_cut, status);
    xadj = std::vector<int>(), adjncy = std::vector<int>();
    check_status(status);
    part.assign(p.begin(), p.end());
    std::vector<long> count(size, 0);
    for (int q : part) ++count[q];
    stats.imbalance = static_cast<double>(*std::max_element(count.begin(), count.end())) * size / n;
  });
  MPI_Bcast(&stats.edge_cut, 1, MPI_LONG, 0, comm);
  MPI_Bcast(&stats.imbalance, 1, MPI_DOUBLE, 0, comm);
  return part;
}


std::vector<int> partition_lattice(const Body& shape, MPI_Comm comm, PartitionStats& stats,
                                   PartitionSpec::Method method) {
  if (method == PartitionSpec::Method::ptscotch) {  // each rank hands over its block's rows, from the stencils: nobody builds the graph
    int rank, size;
    MPI_Comm_rank(comm, &rank);
    MPI_Comm_size(comm, &size);
    const std::int64_t n = shape.molecules();
    std::vector<const TopologyStyle*> style;
    for (int b = 0; b < shape.bodies(); ++b) style.push_back(find_topology(shape.body(b).topology));
    std::vector<Neighbour> nb;
    return ptscotch_block(
        NaturalOrder::block_begin(n, size, rank), NaturalOrder::block_begin(n, size, rank + 1), n,
        [&](std::int64_t g, std::vector<std::int64_t>& out) {
          const int b = shape.body_of(g);
          lattice_neighbours(*style[b], shape.body(b), g, nb);
          for (const auto& x : nb) out.push_back(x.id);
        },
        comm, stats);  // the edge cut: counted by build_local_model from the connections
  }
  // blocks, and auto on one box lattice that it balances: the bisection of the index box, from the box alone
  // (box_bisection.hpp). Every rank decides alike from the box.
  int size;
  MPI_Comm_size(comm, &size);
  if (box_bisection_chosen(shape, method, size)) {
    if (shape.molecules() < size) throw std::runtime_error("the body has fewer molecules than ranks");
    return partition_box_bisection(shape, comm, size, stats);
  }
  return partition_lattice(shape, comm, stats);
}

std::vector<int> partition_lattice(const Body& shape, MPI_Comm comm, PartitionStats& stats) {
  int rank, size;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const std::int64_t n = shape.molecules();
  stats = PartitionStats{};
  const std::int64_t begin = NaturalOrder::block_begin(n, size, rank), end = NaturalOrder::block_begin(n, size, rank + 1);
  std::vector<int> part(end - begin, 0);
  if (size == 1) return part;
  if (n < size) throw std::runtime_error("the body has fewer molecules than ranks");
  // Past 32,768 molecules (more for many ranks), METIS sees blocks of molecules (partition/lattice_blocks.hpp):
  // the molecule graph of the whole lattice on rank 0 cost it about 460 bytes a molecule, and METIS's time.
  if (const int b = lattice_block_size(shape, size); b > 1) return partition_lattice_blocks(shape, comm, size, b, stats);
  if (n > std::numeric_limits<idx_t>::max()) throw std::runtime_error("the body has more molecules than METIS's idx_t holds");

  std::vector<int> all;  // rank 0: the part of every molecule, until scattered
  agree(comm, [&] {  // rank 0 alone, agreed (see partition_molecules)
    if (rank != 0) return;
    fault_point("partition", comm);
    // The same CSR graph as partition_molecules() builds from the global list (neighbours in increasing id),
    // so both paths get the same partition.
    std::vector<idx_t> xadj(n + 1, 0), adjncy;
    std::vector<Neighbour> nb;
    for (int b = 0; b < shape.bodies(); ++b) {
      const BoxGeometry& box = shape.body(b);
      const TopologyStyle& style = *find_topology(box.topology);
      for (std::int64_t g = box.first; g < box.first + box.molecules(); ++g) {
        lattice_neighbours(style, box, g, nb);
        for (const auto& x : nb) adjncy.push_back(static_cast<idx_t>(x.id));
        xadj[g + 1] = static_cast<idx_t>(adjncy.size());
      }
    }
    int status = METIS_OK;
    std::vector<idx_t> p = run_metis(xadj, adjncy, size, stats.edge_cut, status);
    check_status(status);
    all.assign(p.begin(), p.end());
  });
  std::vector<int> counts(size), displs(size);
  for (int r = 0; r < size; ++r) {
    displs[r] = static_cast<int>(NaturalOrder::block_begin(n, size, r));
    counts[r] = static_cast<int>(NaturalOrder::block_begin(n, size, r + 1)) - displs[r];
  }
  MPI_Scatterv(all.data(), counts.data(), displs.data(), MPI_INT, part.data(), counts[rank], MPI_INT, 0, comm);
  MPI_Bcast(&stats.edge_cut, 1, MPI_LONG, 0, comm);
  std::vector<long> count(size, 0), total(size, 0);
  for (int p : part) ++count[p];
  MPI_Allreduce(count.data(), total.data(), size, MPI_LONG, MPI_SUM, comm);
  stats.imbalance = static_cast<double>(*std::max_element(total.begin(), total.end())) * size / n;
  return part;
}

}  // namespace tissue
