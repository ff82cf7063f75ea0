// The lattice multigrid's finest interpolation (level 1 -> the tangent's layout) as a PETSc shell matrix: the
// trilinear weights applied on the fly from a compact list of each fine molecule's coarse nodes, instead of an AIJ
// matrix (3.4 entries a row, 3 rows a molecule: about 137 B a molecule, the largest interpolation by 8x). Kept:
// per fine molecule one byte (its number of coarse nodes and its held components), per coarse node it reads an
// int (where the node's unknowns are: owned or among the ghosts a scatter brings, and its free components) and
// a byte (which of the few distinct weights): about 22 B a molecule. The same operator as setup_lattice_mg's AIJ
// one (held fine components take no correction, held coarse components give none), summed in another order
// (round-off apart). MatMult, MatMultAdd (PCMG's interpolation), MatMultTranspose (its restriction).
#pragma once
#include <petscmat.h>

#include <cstdint>
#include <vector>

namespace tissue {

// Collective. fine_nodes: this rank's owned molecules (rows 3 i + k, local); held: 3 a molecule (at least
// 3 * fine_nodes); per fine molecule i its coarse nodes are entries start[i] .. start[i + 1] - 1 with weights
// weights[which[e]] (at most 256 distinct, taken by the shell) and packed[e] = 8 * (global first unknown of the
// coarse node) + its free-component mask; this rank owns coarse unknowns cfirst .. cfirst + ccount - 1.
PetscErrorCode interpolation_shell(MPI_Comm comm, const std::vector<std::uint8_t>& held, int fine_nodes,
                                   const std::vector<int>& start, std::vector<double>&& weights,
                                   std::vector<std::uint8_t>&& which, const std::vector<PetscInt>& packed,
                                   PetscInt cfirst, PetscInt ccount, Mat* P);
// Collective. c = P^T 1 for a shell P of interpolation_shell (the sums of its columns over free fine components;
// MatMultTranspose's numbers without a fine vector of ones).
PetscErrorCode interpolation_column_sums(Mat P, Vec c);

}  // namespace tissue
