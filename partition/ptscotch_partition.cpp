#include "partition/ptscotch_partition.hpp"

#include <petscmat.h>

#include <algorithm>
#include <stdexcept>
#include <string>

#include "partition/agreement.hpp"

namespace tissue {
namespace {

void check(PetscErrorCode e, const char* what) {
  if (e) throw std::runtime_error(std::string("PETSc failed in ") + what + " (error " + std::to_string(e) + ")");
}

}  // namespace

std::vector<int> ptscotch_block(std::int64_t begin, std::int64_t end, std::int64_t n,
                                const std::function<void(std::int64_t, std::vector<std::int64_t>&)>& neighbours,
                                MPI_Comm comm, PartitionStats& stats) {
  int size;
  MPI_Comm_size(comm, &size);
  stats = PartitionStats{};
  const PetscInt rows = static_cast<PetscInt>(end - begin);
  if (size == 1) return std::vector<int>(rows, 0);
  if (n < size) throw std::runtime_error("the body has fewer molecules than ranks");

  // MatCreateMPIAdj takes the arrays and frees them with PetscFree: they must come from PetscMalloc.
  // This rank's rows, built alone: agreed (partition/agreement.hpp) before the collective partitioning, so that a
  // failure here stops every rank at once. A failure inside PT-Scotch's collectives has only the last resort.
  std::vector<std::int64_t> nb;
  std::vector<PetscInt> cols;
  PetscInt* ia = nullptr;
  PetscInt* ja = nullptr;
  agree(comm, [&] {
    fault_point("partition", comm);
    check(PetscMalloc1(rows + 1, &ia), "PetscMalloc1");
    ia[0] = 0;
    for (PetscInt r = 0; r < rows; ++r) {
      nb.clear();
      neighbours(begin + r, nb);
      std::sort(nb.begin(), nb.end());
      for (auto x : nb) cols.push_back(static_cast<PetscInt>(x));
      ia[r + 1] = static_cast<PetscInt>(cols.size());
    }
    check(PetscMalloc1(std::max<std::size_t>(cols.size(), 1), &ja), "PetscMalloc1");
    std::copy(cols.begin(), cols.end(), ja);
    cols = std::vector<PetscInt>();
  });

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
  std::vector<int> part(owner, owner + rows);
  check(ISRestoreIndices(is, &owner), "ISRestoreIndices");
  check(ISDestroy(&is), "ISDestroy");
  check(MatPartitioningDestroy(&mp), "MatPartitioningDestroy");
  check(MatDestroy(&adj), "MatDestroy");

  std::vector<long> count(size, 0), total(size, 0);
  for (int p : part) ++count[p];
  MPI_Allreduce(count.data(), total.data(), size, MPI_LONG, MPI_SUM, comm);
  if (*std::min_element(total.begin(), total.end()) == 0)
    throw std::runtime_error("PT-Scotch left a rank without molecules; use partition.method = \"metis\"");
  stats.imbalance = static_cast<double>(*std::max_element(total.begin(), total.end())) * size / n;
  return part;
}

}  // namespace tissue
