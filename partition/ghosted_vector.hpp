// A PETSc ghosted vector of block size 3 (x, y, z per molecule; or `width` values a molecule): owned molecules
// first, then ghost copies that update_ghosts() refreshes from their owners. Positions live in one; forces and
// velocities need no ghosts.
#pragma once
#include <petscvec.h>

#include "partition/local_model.hpp"

namespace tissue {

class GhostedVector {
public:
  explicit GhostedVector(const LocalModel& model, int width = 3);
  ~GhostedVector();
  GhostedVector(const GhostedVector&) = delete;
  GhostedVector& operator=(const GhostedVector&) = delete;

  Vec global() const { return vec_; }  // the owned part, as PETSc sees it (for SNES, norms, ...)
  // The local form: width * (owned + ghosts) values, valid for the vector's lifetime.
  double* array() { return array_; }
  const double* array() const { return array_; }
  void update_ghosts();  // owners' values -> ghost copies (collective)
  // Ghost slots' values added to their owners' (collective; a term whose tangent has rows of ghosts). The ghost
  // slots keep their values.
  void add_ghosts_to_owners();

private:
  Vec vec_ = nullptr, local_ = nullptr;
  double* array_ = nullptr;
};

}  // namespace tissue
