#include "src/physics/tangent.hpp"

#include <algorithm>

namespace tissue {

PetscErrorCode TangentStorage::create(const LocalModel& model, Mat* J, const std::vector<std::vector<int>>& extra,
                                      const std::vector<std::vector<PetscInt>>& extra_blocks, bool off_process) {
  PetscFunctionBeginUser;
  const int n = model.owned;
  // Each owned molecule's connections, then its distinct neighbours sorted by block id.
  create_rows(model);
  row_start.assign(n + 1, 0);
  row_cols.clear();
  row_cols.reserve(conn_start[n] + n);
  block_start.assign(extra_blocks.empty() ? 0 : 1, 0);
  row_blocks.clear();
  std::vector<PetscInt> dnnz(n), onnz(n);
  const PetscInt first = model.first_block, last = model.first_block + n;
  auto by_block = [&](int p, int q) { return model.block[p] < model.block[q]; };
  for (int i = 0; i < n; ++i) {
    const std::size_t begin = row_cols.size();
    row_cols.push_back(i);
    for (int p = conn_start[i]; p < conn_start[i + 1]; ++p) {
      const int c = row_conns[p];
      row_cols.push_back(model.end_a[c] == i ? model.end_b[c] : model.end_a[c]);
    }
    if (!extra.empty()) row_cols.insert(row_cols.end(), extra[i].begin(), extra[i].end());
    std::sort(row_cols.begin() + begin, row_cols.end(), by_block);
    row_cols.erase(std::unique(row_cols.begin() + begin, row_cols.end(),
                                [&](int p, int q) { return model.block[p] == model.block[q]; }),
                    row_cols.end());
    row_start[i + 1] = static_cast<int>(row_cols.size());
    dnnz[i] = onnz[i] = 0;
    if (!extra_blocks.empty()) {
      const std::size_t b0 = row_blocks.size();
      for (std::size_t p = begin; p < row_cols.size(); ++p) row_blocks.push_back(model.block[row_cols[p]]);
      row_blocks.insert(row_blocks.end(), extra_blocks[i].begin(), extra_blocks[i].end());
      std::sort(row_blocks.begin() + b0, row_blocks.end());
      row_blocks.erase(std::unique(row_blocks.begin() + b0, row_blocks.end()), row_blocks.end());
      block_start.push_back(static_cast<int>(row_blocks.size()));
      for (std::size_t p = b0; p < row_blocks.size(); ++p) (row_blocks[p] >= first && row_blocks[p] < last ? dnnz[i] : onnz[i])++;
      continue;
    }
    for (std::size_t p = begin; p < row_cols.size(); ++p) {
      const PetscInt bj = model.block[row_cols[p]];
      (bj >= first && bj < last ? dnnz[i] : onnz[i])++;
    }
  }
  row_cols.shrink_to_fit();
  // The pattern in CSR arrays (diagonal part: local columns; off-diagonal part: global columns, sorted), handed
  // to PETSc without copying: MatSetValues costs a visible share of a static run (docs/benchmarks.md).
  // The arrays live here (they are the matrix's storage) and must outlive J.
  di_.assign(3 * n + 1, 0);
  oi_.assign(3 * n + 1, 0);
  for (int i = 0; i < n; ++i)
    for (int r = 0; r < 3; ++r) {
      di_[3 * i + r + 1] = di_[3 * i + r] + 3 * dnnz[i];
      oi_[3 * i + r + 1] = oi_[3 * i + r] + 3 * onnz[i];
    }
  dj_.assign(std::max<PetscInt>(1, di_[3 * n]), 0);
  oj_.assign(std::max<PetscInt>(1, oi_[3 * n]), 0);
  dv_.assign(dj_.size(), 0.0);
  ov_.assign(oj_.size(), 0.0);
  for (int i = 0; i < n; ++i)
    for (int r = 0; r < 3; ++r) {
      PetscInt d = di_[3 * i + r], o = oi_[3 * i + r];
      const bool whole = !block_start.empty();
      for (int p = whole ? block_start[i] : row_start[i]; p < (whole ? block_start[i + 1] : row_start[i + 1]); ++p) {
        const PetscInt bj = whole ? row_blocks[p] : model.block[row_cols[p]];
        for (int s = 0; s < 3; ++s) {
          if (bj >= first && bj < last)
            dj_[d++] = 3 * (bj - first) + s;
          else
            oj_[o++] = 3 * bj + s;
        }
      }
    }
  if (model.size > 1) {
    PetscCall(MatCreateMPIAIJWithSplitArrays(model.comm, 3 * n, 3 * n, PETSC_DETERMINE, PETSC_DETERMINE,
                                             di_.data(), dj_.data(), dv_.data(), oi_.data(),
                                             oj_.data(), ov_.data(), J));
  } else {
    PetscCall(MatCreateSeqAIJWithArrays(model.comm, 3 * n, 3 * n, di_.data(), dj_.data(), dv_.data(), J));
  }
  {
    // The arrays are freed when J is (a container composed with J), not kept for the ForceModel's lifetime.
    PetscContainer owner;
    PetscCall(PetscContainerCreate(PETSC_COMM_SELF, &owner));
    PetscCall(PetscContainerSetPointer(owner, this));
    PetscCall(PetscContainerSetUserDestroy(owner, [](void* p) -> PetscErrorCode {
      static_cast<TangentStorage*>(p)->release_arrays();
      return 0;
    }));
    PetscCall(PetscObjectCompose(reinterpret_cast<PetscObject>(*J), "tissue_tangent_arrays",
                                 reinterpret_cast<PetscObject>(owner)));
    PetscCall(PetscContainerDestroy(&owner));
  }
  PetscCall(MatSetBlockSize(*J, 3));  // AIJ with block size 3: what GAMG wants (not BAIJ)
  PetscCall(MatSetOption(*J, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(MatSetOption(*J, MAT_SYMMETRY_ETERNAL, PETSC_TRUE));
  PetscCall(MatSetOption(*J, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  // Owned rows only: assembly sends nothing (unless a term adds rows of ghosts).
  if (!off_process) PetscCall(MatSetOption(*J, MAT_NO_OFF_PROC_ENTRIES, PETSC_TRUE));
  PetscCall(MatAssemblyBegin(*J, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(*J, MAT_FINAL_ASSEMBLY));
  // The direct writes rely on each scalar row holding, in the diagonal part, 3 columns per on-rank block
  // column in block order, and in the off-diagonal part the same for the off-rank ones (PETSc keeps those
  // sorted by global column): checked here once.
  Mat Ad, Ao;
  PetscCall(aij_parts(*J, &Ad, &Ao));
  for (Mat part : {Ad, Ao}) {
    if (!part) continue;
    const PetscInt *ia, *ja;
    PetscInt rows;
    PetscBool done;
    PetscCall(MatGetRowIJ(part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &ia, &ja, &done));
    PetscCheck(done && rows == 3 * n, model.comm, PETSC_ERR_PLIB, "tangent: no row structure");
    for (int i = 0; i < n; ++i)
      for (int r = 0; r < 3; ++r)
        PetscCheck(ia[3 * i + r + 1] - ia[3 * i + r] == 3 * (part == Ad ? dnnz[i] : onnz[i]), model.comm,
                   PETSC_ERR_PLIB, "tangent: the assembled pattern is not the preallocated one");
    PetscCall(MatRestoreRowIJ(part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &ia, &ja, &done));
  }
  PetscFunctionReturn(0);
}

void TangentStorage::create_rows(const LocalModel& model) {
  const int n = model.owned, nc = model.connections();
  // A counting sort of the connections by owned end.
  conn_start.assign(n + 1, 0);
  for (int c = 0; c < nc; ++c) {
    if (model.end_a[c] < n) conn_start[model.end_a[c] + 1]++;
    if (model.end_b[c] < n) conn_start[model.end_b[c] + 1]++;
  }
  for (int i = 0; i < n; ++i) conn_start[i + 1] += conn_start[i];
  row_conns.assign(conn_start[n], 0);
  std::vector<int> fill(conn_start.begin(), conn_start.end() - 1);
  for (int c = 0; c < nc; ++c) {
    if (model.end_a[c] < n) row_conns[fill[model.end_a[c]]++] = c;
    if (model.end_b[c] < n) row_conns[fill[model.end_b[c]]++] = c;
  }
}

void TangentStorage::release_arrays() {
  for (auto* v : {&di_, &dj_, &oi_, &oj_}) std::vector<PetscInt>().swap(*v);
  for (auto* v : {&dv_, &ov_}) std::vector<PetscScalar>().swap(*v);
}

// The diagonal and off-diagonal SeqAIJ parts of an AIJ matrix (one rank: the matrix itself, no off-diagonal part).
PetscErrorCode aij_parts(Mat J, Mat* Ad, Mat* Ao) {
  PetscFunctionBeginUser;
  PetscBool mpi = PETSC_FALSE;
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(J), MATMPIAIJ, &mpi));
  *Ao = nullptr;
  if (mpi) {
    PetscCall(MatMPIAIJGetSeqAIJ(J, Ad, Ao, nullptr));
  } else {
    *Ad = J;
  }
  PetscFunctionReturn(0);
}

}  // namespace tissue
