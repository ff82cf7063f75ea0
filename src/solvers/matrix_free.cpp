#include "src/solvers/matrix_free.hpp"

#include <cstring>
#include <exception>

namespace tissue {

MatrixFreeTangent::MatrixFreeTangent(const LocalModel& model, const ForceModel& forces)
    : model_(model), forces_(forces), x_(model.rest.begin(), model.rest.begin() + 3 * model.local), in_(model) {}

MatrixFreeTangent::~MatrixFreeTangent() = default;

PetscErrorCode MatrixFreeTangent::create(Mat* J) {
  PetscFunctionBeginUser;
  const PetscInt n = 3 * model_.owned;
  PetscCall(MatCreateShell(model_.comm, n, n, PETSC_DETERMINE, PETSC_DETERMINE, this, J));
  PetscCall(MatShellSetOperation(*J, MATOP_MULT, reinterpret_cast<void (*)(void)>(mult)));
  PetscCall(MatShellSetOperation(*J, MATOP_MULT_TRANSPOSE, reinterpret_cast<void (*)(void)>(mult)));
  PetscCall(MatShellSetOperation(*J, MATOP_GET_DIAGONAL, reinterpret_cast<void (*)(void)>(diagonal)));
  PetscCall(MatSetBlockSize(*J, 3));
  PetscCall(MatSetOption(*J, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(MatSetOption(*J, MAT_SYMMETRY_ETERNAL, PETSC_TRUE));
  PetscFunctionReturn(0);
}

PetscErrorCode MatrixFreeTangent::set_positions(const double* x, Mat J) {
  PetscFunctionBeginUser;
  std::memcpy(x_.data(), x, sizeof(double) * x_.size());
  PetscCall(MatAssemblyBegin(J, MAT_FINAL_ASSEMBLY));  // a new state: PCSetUp sees a changed operator
  PetscCall(MatAssemblyEnd(J, MAT_FINAL_ASSEMBLY));
  PetscFunctionReturn(0);
}

PetscErrorCode MatrixFreeTangent::mult(Mat J, Vec in, Vec out) {
  PetscFunctionBeginUser;
  MatrixFreeTangent* self;
  PetscCall(MatShellGetContext(J, &self));
  const PetscScalar* u;
  PetscCall(VecGetArrayRead(in, &u));
  std::memcpy(self->in_.array(), u, sizeof(double) * 3 * self->model_.owned);
  PetscCall(VecRestoreArrayRead(in, &u));
  try {
    self->in_.update_ghosts();
  } catch (const std::exception& e) {
    SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "%s", e.what());
  }
  PetscScalar* y;
  PetscCall(VecGetArray(out, &y));
  PetscCall(self->forces_.apply_tangent(self->x_.data(), self->in_.array(), y));
  PetscCall(VecRestoreArray(out, &y));
  PetscFunctionReturn(0);
}

PetscErrorCode MatrixFreeTangent::diagonal(Mat J, Vec d) {
  PetscFunctionBeginUser;
  MatrixFreeTangent* self;
  PetscCall(MatShellGetContext(J, &self));
  PetscScalar* y;
  PetscCall(VecGetArray(d, &y));
  PetscCall(self->forces_.tangent_diagonal(self->x_.data(), y));
  PetscCall(VecRestoreArray(d, &y));
  PetscFunctionReturn(0);
}

}  // namespace tissue
