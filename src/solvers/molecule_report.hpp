// Reports that name a molecule: where a solve went wrong, in words, the same text on every rank (the guards'
// and the solvers' failure messages), with the few MPI helpers they share with the set-up checks.
#pragma once
#include <mpi.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "partition/local_model.hpp"

namespace tissue {

// This process's rank in comm.
int rank_of(MPI_Comm comm);

// The same string on every rank, from `root`.
std::string broadcast(const std::string& s, int root, MPI_Comm comm);

// Collective: the original id of the owned molecule with the largest `value` (NaN counts as largest; ties: the
// smallest id), or -1 when no rank has any molecule.
std::int64_t argmax_molecule(const LocalModel& model, const std::vector<double>& value);

// The length of the connection between local molecules a and b at positions x.
inline double length_of(const double* x, int a, int b) {
  const double d0 = x[3 * b] - x[3 * a], d1 = x[3 * b + 1] - x[3 * a + 1], d2 = x[3 * b + 2] - x[3 * a + 2];
  return std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
}

// Collective. "molecule M at (x, y, z); connection C (molecules A-B) strain S": the connection with the largest
// |strain| (non-finite counts as largest) among those of molecule M (original id), from local positions x (ghosts
// up to date). Every rank returns the same text.
std::string describe_molecule(const LocalModel& model, const double* x, std::int64_t molecule);

// Collective. The original id of the owned molecule with the largest |f| (free components), over all ranks.
std::int64_t largest_force_molecule(const LocalModel& model, const double* f);

}  // namespace tissue
