// The Newton tangent as a PETSc shell matrix: J u applied from the current positions and the connections (and
// every term's blocks, through Term::add_tangent) without storing J, so a static solve on a lattice keeps no
// fine-level matrix (the lattice multigrid's coarse operators come from the same block stream,
// LatticeGalerkin::update(forces, x, pc)). It is the matrix assemble_tangent would fill: held components' rows
// and columns are the identity's. MatMult and MatGetDiagonal only: the smoothers on it are Chebyshev on Jacobi.
#pragma once
#include <petscmat.h>

#include <vector>

#include "partition/ghosted_vector.hpp"
#include "partition/local_model.hpp"
#include "src/physics/force_model.hpp"

namespace tissue {

class MatrixFreeTangent {
public:
  MatrixFreeTangent(const LocalModel& model, const ForceModel& forces);
  ~MatrixFreeTangent();
  MatrixFreeTangent(const MatrixFreeTangent&) = delete;
  MatrixFreeTangent& operator=(const MatrixFreeTangent&) = delete;

  // Collective. The shell matrix (3 unknowns a molecule in owned order, block size 3, symmetric); it refers to
  // this object, which must outlive it.
  PetscErrorCode create(Mat* J);
  // The positions J is taken at (3 * local, ghosts up to date): copied, so later force evaluations (line
  // search) do not move it. Marks J changed (a preconditioner set up on it is stale).
  PetscErrorCode set_positions(const double* x, Mat J);
  const double* positions() const { return x_.data(); }

private:
  static PetscErrorCode mult(Mat J, Vec in, Vec out);
  static PetscErrorCode diagonal(Mat J, Vec d);
  const LocalModel& model_;
  const ForceModel& forces_;
  std::vector<double> x_;
  GhostedVector in_;  // the input with its ghosts
};

}  // namespace tissue
