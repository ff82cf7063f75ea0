#include "partition/ghosted_vector.hpp"

#include <stdexcept>

namespace tissue {

namespace {
void check(PetscErrorCode ierr, const char* what) {
  if (ierr) throw std::runtime_error(std::string("PETSc failed in ") + what);
}
}  // namespace

GhostedVector::GhostedVector(const LocalModel& model, int width) {
  std::vector<PetscInt> ghosts = model.block.slice(model.owned, model.local);
  check(VecCreateGhostBlock(model.comm, width, width * model.owned, PETSC_DECIDE, static_cast<PetscInt>(ghosts.size()),
                            ghosts.data(), &vec_), "VecCreateGhostBlock");
  // The local form stays open for the vector's lifetime: the kernels read and write it directly.
  check(VecGhostGetLocalForm(vec_, &local_), "VecGhostGetLocalForm");
  check(VecGetArray(local_, &array_), "VecGetArray");
}

GhostedVector::~GhostedVector() {
  if (local_) {
    VecRestoreArray(local_, &array_);
    VecGhostRestoreLocalForm(vec_, &local_);
  }
  if (vec_) VecDestroy(&vec_);
}

void GhostedVector::update_ghosts() {
  // The array stays borrowed from the local form, which shares memory with the global vector: the scatter
  // writes the ghost slots in place.
  check(VecGhostUpdateBegin(vec_, INSERT_VALUES, SCATTER_FORWARD), "VecGhostUpdateBegin");
  check(VecGhostUpdateEnd(vec_, INSERT_VALUES, SCATTER_FORWARD), "VecGhostUpdateEnd");
}

}  // namespace tissue


namespace tissue {

void GhostedVector::add_ghosts_to_owners() {
  check(VecGhostUpdateBegin(vec_, ADD_VALUES, SCATTER_REVERSE), "VecGhostUpdateBegin");
  check(VecGhostUpdateEnd(vec_, ADD_VALUES, SCATTER_REVERSE), "VecGhostUpdateEnd");
}

}  // namespace tissue
