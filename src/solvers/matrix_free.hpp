// The Newton tangent as a PETSc shell matrix: J u applied from the current positions and the connections (and
// every term's blocks, through Term::add_tangent) without storing J, so a static solve on a lattice keeps no
// fine-level matrix (the lattice multigrid's coarse operators come from the same block stream,
// LatticeGalerkin::update(forces, x, pc)). It is the matrix assemble_tangent would fill: held components' rows
// and columns are the identity's. MatMult and MatGetDiagonal only: the smoothers on it are Chebyshev on Jacobi.
// In scenes with a term worth caching (Term::tangent_worth_caching: the cell term) every term's blocks are computed
// once per Newton iteration, in set_positions, and kept per owned molecule (up to 27, a lattice stencil: 2,052 B a
// molecule, only in such scenes); the springs' blocks are recomputed on every product. Where every term applies its
// own product from a smaller state (Term::has_tangent_state: the cell term's dP/dF, 648 B a cell), that state is
// kept instead of the blocks; the first such term's product runs inside the springs' sweep, a piece as soon as the
// springs' part of its rows is final (Term::apply_tangent_state_below), so one pass over u, x and out does both
// (the same bits as the two passes).
#pragma once
#include <petscmat.h>

#include <vector>

#include "partition/local_model.hpp"
#include "src/physics/force_model.hpp"

namespace tissue {

class MatrixFreeTangent {
public:
  // scratch (optional): 3 * model.local doubles that nothing reads across a product (the Newton solve's force
  // array: each residual evaluation writes it whole before reading it), used as the products' ghosted input
  // instead of an array of the shell's own (24 B a molecule).
  // rest (kept by the caller, exact: SpringKernel::rest_stencil): the tangent at the rest positions, the springs'
  // part from its constants (src/solvers/rest_tangent.hpp); set_positions(model.rest) once, then never again.
  MatrixFreeTangent(const LocalModel& model, const ForceModel& forces, double* scratch = nullptr,
                    const RestStencil* rest = nullptr);
  ~MatrixFreeTangent();
  MatrixFreeTangent(const MatrixFreeTangent&) = delete;
  MatrixFreeTangent& operator=(const MatrixFreeTangent&) = delete;

  // Collective. The shell matrix (3 unknowns a molecule in owned order, block size 3, symmetric); it refers to
  // this object, which must outlive it.
  PetscErrorCode create(Mat* J);
  // The positions J is taken at (3 * local, ghosts up to date): not copied (3 doubles a molecule saved), so x must
  // not change while J is applied. SNES keeps to that: it computes the tangent at the iterate, solves, and only
  // then moves the positions (line search), and the next iteration's tangent comes first. Marks J changed (a
  // preconditioner set up on it is stale). Computes the cached terms' blocks at x.
  PetscErrorCode set_positions(const double* x, Mat J);
  const double* positions() const { return x_; }

private:
  static PetscErrorCode mult(Mat J, Vec in, Vec out);
  static PetscErrorCode diagonal(Mat J, Vec d);
  PetscErrorCode cache_blocks();
  const LocalModel& model_;
  const ForceModel& forces_;
  const RestStencil* rest_;
  const double* x_;
  std::vector<double> own_;  // the input's storage when no scratch is given
  Vec in_ = nullptr;         // the input with its ghosts (a ghosted vector over scratch or own_)
  double* w_ = nullptr;      // its array
  // The terms' blocks at x_ (empty without a term worth caching): per owned molecule up to kSlots columns (local
  // molecule; -1 ends the row) and their 3x3 blocks, duplicates summed, held rows and columns zero.
  static constexpr int kSlots = 27;
  const bool cached_;
  // Every term applies its own product (Term::has_tangent_state): their states at x_, in the terms' order.
  const bool by_state_;
  std::vector<std::vector<double>> state_;
  std::vector<double> held_out_;  // mult's copy of the held rows' values while the terms add theirs
  std::vector<double> held_in_;   // mult's copy of the input's owned held values (put back after the product)
  std::vector<int> cache_col_;
  std::vector<double> cache_K_;
};

}  // namespace tissue
