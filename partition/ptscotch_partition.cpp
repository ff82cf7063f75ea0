#include "partition/ptscotch_partition.hpp"

#include <petscmat.h>

#include <algorithm>
#include <stdexcept>
#include <string>

namespace tissue {
namespace {

void check(PetscErrorCode e, const char* what) {
  if (e) throw std::runtime_error(std::string("PETSc failed in ") + what + " (error " + std::to_string(e) + ")");
}

}  // namespace

std::vector<int> partition_ptscotch(const Body& body, MPI_Comm comm, PartitionStats& stats) {
  int rank, size;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const std::int64_t n = body.molecules();
  std::vector<int> part(n, 0);
  stats = PartitionStats{};
  if (size == 1) return part;
  if (n < size) throw std::runtime_error("the body has fewer molecules than ranks");

  // This rank's rows: an even block of molecule ids.
  const std::int64_t lo = n * rank / size, hi = n * (rank + 1) / size;
  const PetscInt rows = static_cast<PetscInt>(hi - lo);
  std::vector<PetscInt> degree(rows, 0);
  for (const auto& c : body.connections) {
    if (c.a >= lo && c.a < hi) ++degree[c.a - lo];
    if (c.b >= lo && c.b < hi) ++degree[c.b - lo];
  }
  // MatCreateMPIAdj takes the arrays and frees them with PetscFree: they must come from PetscMalloc.
  PetscInt *ia = nullptr, *ja = nullptr;
  check(PetscMalloc1(rows + 1, &ia), "PetscMalloc1");
  ia[0] = 0;
  for (PetscInt r = 0; r < rows; ++r) ia[r + 1] = ia[r] + degree[r];
  check(PetscMalloc1(std::max<PetscInt>(ia[rows], 1), &ja), "PetscMalloc1");
  std::vector<PetscInt> fill(ia, ia + rows);
  for (const auto& c : body.connections) {  // sorted by (a, b): each row's columns come out sorted after a merge
    if (c.a >= lo && c.a < hi) ja[fill[c.a - lo]++] = static_cast<PetscInt>(c.b);
    if (c.b >= lo && c.b < hi) ja[fill[c.b - lo]++] = static_cast<PetscInt>(c.a);
  }
  for (PetscInt r = 0; r < rows; ++r) std::sort(ja + ia[r], ja + ia[r + 1]);

  Mat adj;
  MatPartitioning mp;
  IS is;
  check(MatCreateMPIAdj(comm, rows, static_cast<PetscInt>(n), ia, ja, nullptr, &adj), "MatCreateMPIAdj");
  check(MatPartitioningCreate(comm, &mp), "MatPartitioningCreate");
  check(MatPartitioningSetAdjacency(mp, adj), "MatPartitioningSetAdjacency");
  check(MatPartitioningSetType(mp, MATPARTITIONINGPTSCOTCH), "MatPartitioningSetType(ptscotch)");
  check(MatPartitioningSetNParts(mp, size), "MatPartitioningSetNParts");
  check(MatPartitioningApply(mp, &is), "MatPartitioningApply");
  const PetscInt* owner;
  check(ISGetIndices(is, &owner), "ISGetIndices");
  std::vector<int> mine(owner, owner + rows);
  check(ISRestoreIndices(is, &owner), "ISRestoreIndices");
  check(ISDestroy(&is), "ISDestroy");
  check(MatPartitioningDestroy(&mp), "MatPartitioningDestroy");
  check(MatDestroy(&adj), "MatDestroy");

  // Every rank needs the whole owner map (distribute reads it): gather the blocks in rank order.
  std::vector<int> counts(size), displs(size);
  for (int r = 0; r < size; ++r) {
    displs[r] = static_cast<int>(n * r / size);
    counts[r] = static_cast<int>(n * (r + 1) / size) - displs[r];
  }
  MPI_Allgatherv(mine.data(), static_cast<int>(rows), MPI_INT, part.data(), counts.data(), displs.data(), MPI_INT,
                 comm);
  for (const auto& c : body.connections) stats.edge_cut += part[c.a] != part[c.b];
  std::vector<long> count(size, 0);
  for (int p : part) ++count[p];
  if (*std::min_element(count.begin(), count.end()) == 0)
    throw std::runtime_error("PT-Scotch left a rank without molecules; use partition.method = \"metis\"");
  stats.imbalance = static_cast<double>(*std::max_element(count.begin(), count.end())) * size / n;
  return part;
}

}  // namespace tissue
