// A PETSc ghosted vector of block size 3 (x, y, z per molecule): owned molecules first, then ghost copies that
// update_ghosts() refreshes from their owners. Positions live in one; forces and velocities need no ghosts.
#pragma once
#include <petscvec.h>

#include "partition/local_model.hpp"

namespace tissue {

class GhostedVector {
public:
  explicit GhostedVector(const LocalModel& model);
  ~GhostedVector();
  GhostedVector(const GhostedVector&) = delete;
  GhostedVector& operator=(const GhostedVector&) = delete;

  Vec global() const { return vec_; }  // the owned part, as PETSc sees it (for SNES, norms, ...)
  // The local form: 3 * (owned + ghosts) values, valid between get and restore.
  double* array() { return array_; }
  const double* array() const { return array_; }
  void update_ghosts();  // owners' values -> ghost copies (collective)

private:
  Vec vec_ = nullptr, local_ = nullptr;
  double* array_ = nullptr;
};

}  // namespace tissue
