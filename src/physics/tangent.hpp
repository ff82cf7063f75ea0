// The tangent's storage: the block-row pattern of -dF/dx over the connections (each owned molecule's columns and
// connections) and the CSR arrays of the AIJ matrix made from it, handed to PETSc without copying. The values
// are ForceModel::assemble_tangent's.
#pragma once
#include <petscmat.h>

#include <vector>

#include "partition/local_model.hpp"

namespace tissue {

class TangentStorage {
public:
  // Collective. The pattern of the model's connections and J: AIJ, block size 3, exactly preallocated, whose
  // arrays are held here until J is destroyed (J must not outlive this object).
  // extra: per owned row, local columns beyond its connections' (terms' couplings; may be empty); extra_blocks:
  // per owned row, PETSc block ids of columns that need not be local (couplings two rings deep; may be empty);
  // off_process: some rank adds rows it does not own (PETSc moves them at assembly).
  PetscErrorCode create(const LocalModel& model, Mat* J, const std::vector<std::vector<int>>& extra = {},
                        const std::vector<std::vector<PetscInt>>& extra_blocks = {}, bool off_process = false);
  // Only each owned molecule's connections (conn_start, row_conns): what the matrix-free tangent needs.
  void create_rows(const LocalModel& model);

  // The tangent's block rows (built by create): row i's columns are the local molecules
  // row_cols[row_start[i] .. row_start[i+1]) sorted by PETSc block id, itself included; its connections are
  // row_conns[conn_start[i] .. conn_start[i+1]). Row-wise assembly then sets each row once, in order.
  std::vector<int> row_start, row_cols, conn_start, row_conns;
  // With extra_blocks only: each row's whole pattern, PETSc block ids ascending (row_cols's and the others'),
  // row_blocks[block_start[i] .. block_start[i+1]).
  std::vector<int> block_start;
  std::vector<PetscInt> row_blocks;

private:
  // The tangent's CSR arrays, diagonal (d) and off-diagonal (o) parts: the storage of the matrix create makes
  // (PETSc does not copy them); released when that matrix is destroyed.
  std::vector<PetscInt> di_, dj_, oi_, oj_;
  std::vector<PetscScalar> dv_, ov_;
  void release_arrays();
};

// The diagonal and off-diagonal SeqAIJ parts of an AIJ matrix (one rank: the matrix itself, no off-diagonal part).
PetscErrorCode aij_parts(Mat J, Mat* Ad, Mat* Ao);

}  // namespace tissue
