// A PETSc ghosted vector of block size 3 (x, y, z per molecule; or `width` values a molecule): owned molecules
// first, then ghost copies that update_ghosts() refreshes from their owners. Positions live in one; forces and
// velocities need no ghosts.
#pragma once
#include <petscvec.h>

#include <cstddef>
#include <vector>

#include "partition/exchange.hpp"
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

// The same ghost update for positions held as three streams (x[d * stride + i], d = 0, 1, 2: the explicit
// solver's fused step, src/solvers/dynamic.cpp), where the PETSc scatter, which moves blocks of 3 contiguous
// values, does not apply: each ghost's owner sends its 3 values with one MPI_Alltoallv a call. The values are
// copies, so the ghosts get the same bits as update_ghosts() gives. Collective, the constructor too (one exchange
// of the ghosts' block ids to their owners).
class StreamGhosts {
public:
  explicit StreamGhosts(const LocalModel& model);
  void update(double* x, std::size_t stride);  // owners' values -> ghost copies (collective)

private:
  ExchangePlan plan_;           // items: ghosts, from the rank holding the copy to the owner
  std::vector<int> send_rows_;  // per item received: the owned molecule to send back
  std::vector<int> ghost_rows_; // per item sent: the ghost slot its values fill
  std::vector<double> out_, in_;
};

}  // namespace tissue
