#include "partition/metis_partition.hpp"

#include <metis.h>

#include <algorithm>
#include <stdexcept>
#include <string>

#include "partition/ptscotch_partition.hpp"

namespace tissue {

std::vector<int> partition_molecules(const Body& body, MPI_Comm comm, PartitionStats& stats) {
  int rank, size;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const std::int64_t n = body.molecules();
  std::vector<int> part(n, 0);
  stats = PartitionStats{};
  if (size == 1) return part;
  if (n < size) throw std::runtime_error("the body has fewer molecules than ranks");

  int status = METIS_OK;
  if (rank == 0) {
    // The connection graph in CSR form, both directions.
    std::vector<idx_t> xadj(n + 1, 0), adjncy(2 * body.connections.size());
    for (const auto& c : body.connections) ++xadj[c.a + 1], ++xadj[c.b + 1];
    for (std::int64_t m = 0; m < n; ++m) xadj[m + 1] += xadj[m];
    std::vector<idx_t> fill(xadj.begin(), xadj.end() - 1);
    for (const auto& c : body.connections) {
      adjncy[fill[c.a]++] = static_cast<idx_t>(c.b);
      adjncy[fill[c.b]++] = static_cast<idx_t>(c.a);
    }
    idx_t nvtxs = static_cast<idx_t>(n), ncon = 1, nparts = size, objval = 0;
    idx_t options[METIS_NOPTIONS];
    METIS_SetDefaultOptions(options);
    options[METIS_OPTION_SEED] = 1;  // the same partition every run
    std::vector<idx_t> p(n);
    status = METIS_PartGraphKway(&nvtxs, &ncon, xadj.data(), adjncy.data(), nullptr, nullptr, nullptr, &nparts,
                                 nullptr, nullptr, options, &objval, p.data());
    std::copy(p.begin(), p.end(), part.begin());
    stats.edge_cut = objval;
  }
  MPI_Bcast(&status, 1, MPI_INT, 0, comm);
  if (status != METIS_OK) throw std::runtime_error("METIS_PartGraphKway failed with status " + std::to_string(status));
  MPI_Bcast(part.data(), static_cast<int>(n), MPI_INT, 0, comm);
  MPI_Bcast(&stats.edge_cut, 1, MPI_LONG, 0, comm);
  std::vector<long> count(size, 0);
  for (int p : part) ++count[p];
  stats.imbalance = static_cast<double>(*std::max_element(count.begin(), count.end())) * size / n;
  return part;
}

std::vector<int> partition_molecules(const Body& body, MPI_Comm comm, PartitionStats& stats,
                                     const std::string& method) {
  return method == "ptscotch" ? partition_ptscotch(body, comm, stats) : partition_molecules(body, comm, stats);
}

}  // namespace tissue
