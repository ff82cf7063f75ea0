// The lattice multigrid's Galerkin coarse operators P^T A P computed from the lattice's structure instead of by a
// general sparse triple product (hypre's or PETSc's). The interpolation is trilinear in the lattice plane
// indices with the same weight for the three components (lattice_mg.hpp), and the tangent couples a molecule
// only to molecules at most one plane away along each axis, so every operator in the hierarchy is a 27-point
// stencil of 3x3 blocks in its own level's plane indices: each coarse block is a sum of w_iI w_jJ A_ij over the
// fine blocks, computed a 3x3 block at a time with no index search (a general product works entry by entry,
// and at 64,000 molecules hypre's took about as many instructions as all the solve's matrix-vector products).
// Held components are rows and columns of zeros in the blocks (the identity rows of the tangent are dropped),
// which is exactly the masked interpolation lattice_mg.cpp builds. Applies only when every block of the fine
// operator joins molecules of one box at most one plane apart (applies()); otherwise PCMG's own product stays.
#pragma once
#include <petscpc.h>

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "partition/local_model.hpp"
#include "src/physics/force_model.hpp"
#include "src/solvers/lattice_mg.hpp"

namespace tissue {

class LatticeGalerkin {
public:
  LatticeGalerkin(const LocalModel& model, const std::vector<std::uint8_t>& held, LatticeLevels levels);
  ~LatticeGalerkin();
  LatticeGalerkin(const LatticeGalerkin&) = delete;
  LatticeGalerkin& operator=(const LatticeGalerkin&) = delete;

  // Collective. Whether fine (the tangent: AIJ, 3 unknowns a molecule in owned order) is a lattice stencil.
  PetscErrorCode applies(Mat fine, bool* ok) const;
  // Collective. The coarse operators of every level from fine's current values, set as the operators of pc's
  // (a PCMG with this hierarchy) coarser levels; the matrices are made on the first call and refilled after.
  PetscErrorCode update(Mat fine, PC pc);
  // Collective. The same with no fine matrix (the matrix-free tangent, src/solvers/matrix_free.hpp): the fine
  // blocks from forces.tangent_blocks at positions x (local, ghosts up to date), summed into the level-1 rows.
  PetscErrorCode update(const ForceModel& forces, const double* x, PC pc);
  // Collective. Whether every block forces.tangent_blocks gives at x joins molecules of one box at most one plane
  // apart (what update(forces, x, pc) needs).
  PetscErrorCode applies(const ForceModel& forces, const double* x, bool* ok) const;
  // From the next update on, level 1 (when it is not the coarsest) is a shell matrix over its stencil rows, which
  // level 2 is summed from anyway: no CSR copy of it (about 360 B a fine molecule, the largest matrix of the
  // matrix-free solve), and once level 2 is summed only the rows' upper half (symmetric: 126 B a fine molecule
  // instead of 243). Its MatMult and diagonal only: Chebyshev-Jacobi smoothing and its estimator need no more.
  void keep_level_one_as_stencil() { stencil_level_one_ = true; }
  // After update(forces, x, pc): Gershgorin's bound on the Jacobi-scaled fine operator, summed from the same block
  // stream (the same numbers as ForceModel::jacobi_gershgorin's own pass when the force model has no terms and no
  // cached tangent, which then need not stream the blocks again).
  double jacobi_bound() const { return jacobi_bound_; }
  // After update(forces, x, pc): the largest eigenvalue of the Jacobi-scaled fine operator's symbol (its
  // Fourier transform, a 3x3 Hermitian matrix a wave vector), the largest over the fine rows whose 27 blocks are
  // all present between wholly free molecules, as if each such row were repeated over an infinite lattice
  // (every rank's; 0 when there is no such row, or too many distinct ones to look at: a deformed state). What an
  // eigenvalue estimate of the interior would give, without its products (docs/poisson.md).
  double symbol_bound() const { return symbol_bound_; }
  // Level 1's nodes on this rank whose product is pulled (summed in registers, 8 at a time; 0 without the shell,
  // with -static_level_one_pull false, or where no node qualifies): the same bits as the push form either way.
  std::size_t level_one_pulled() const;

private:
  struct Rows;
  struct Numbers;
  struct Neighbours;
  struct StencilOperator;  // level 1 as its rows behind a shell (keep_level_one_as_stencil)
  struct Stream {  // the fine blocks' source when there is no fine matrix
    const ForceModel* forces;
    const double* x;
  };
  PetscErrorCode update(Mat fine, const Stream* stream, PC pc);
  PetscErrorCode coarsen(int l, Mat fine, const Stream* stream, const Rows* stencil, Rows& next);
  // coarsen's steps, in order (lattice_galerkin.cpp narrates each).
  PetscErrorCode accumulate_rows(int l, Mat fine, const Stream* stream, const Rows* stencil, Rows& acc) const;
  PetscErrorCode number_coarse_nodes(int l, const Rows& acc, Numbers& num) const;
  PetscErrorCode send_rows_to_owners(int l, const Numbers& numbers, Rows& acc) const;
  PetscErrorCode mask_held(int l, const Numbers& num, Rows& acc, std::vector<PetscInt>& dnnz,
                           std::vector<PetscInt>& onnz) const;
  PetscErrorCode fill_coarse_matrix(int l, const Numbers& num, const Rows& acc, const std::vector<PetscInt>& dnnz,
                                    const std::vector<PetscInt>& onnz);
  void neighbours(int l, const Numbers& num, const Rows& acc, std::size_t c, Neighbours& nb) const;
  PetscErrorCode stencil_operator(const Numbers& num, const Rows& acc);
  void halve_level_one();
  void pull_runs();
  static PetscErrorCode stencil_mult(Mat A, Vec in, Vec out);
  static PetscErrorCode stencil_diagonal(Mat A, Vec d);

  const LocalModel& model_;
  const std::vector<std::uint8_t>& held_;
  LatticeLevels levels_;
  void index_molecules() const;                  // fills ijk_, for the length of one call
  mutable std::vector<std::array<int, 3>> ijk_;  // lattice indices of every local molecule (ghosts too)
  struct Csr {
    std::vector<PetscInt> di, dj, oi, oj;
    std::vector<PetscScalar> dv, ov;
  };
  std::vector<Csr> csr_;     // the storage of coarse_ (PETSc does not copy it): destroyed after the matrices
  std::vector<Mat> coarse_;  // coarse_[l]: the operator of level l (l >= 1; coarse_[0] unused)
  bool stencil_level_one_ = false;
  mutable double symbol_bound_ = 0.0;  // this rank's while the stream runs, then every rank's (-1: too many rows)
  mutable double jacobi_bound_ = 0.0;  // this rank's while the stream runs (accumulate_rows), then every rank's
  std::unique_ptr<StencilOperator> level_one_;  // when level 1 is a shell: its rows, columns and ghost scatter
};

}  // namespace tissue
