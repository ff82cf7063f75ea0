// The lattice multigrid's finest-level smoother for near-incompressible cells (issue 15, docs/poisson.md): the
// preconditioner inside the finest level's Chebyshev that holds each cell's volume coupling k_c b_c b_c^T (the cell
// term's volumetric part, Term::volume_coupling) exactly instead of only through the diagonal. Summed over all
// cells the smoother's matrix is M = D + B^T K B (D the tangent's diagonal less the cells' volumetric part, B the
// cells' divergences as rows, K = diag(k_c)), applied by Woodbury:
//   M^-1 = D^-1 - D^-1 B^T Q B D^-1,  Q ~ T^-1,  T = K^-1 + B D^-1 B^T (the cells' Schur complement),
// Q = m steps of the Neumann series of omega diag(T)^-1 (omega = 1 / (1.05 lambda_max(diag(T)^-1 T)), a power
// iteration at set-up), so Q < T^-1 and M stays SPD (Chebyshev's estimate runs CG on it). Point Jacobi's diagonal
// scales with lambda + 2 mu, so an oscillating volume-preserving error, which only mu resists, lies below Chebyshev's
// interval once lambda >> mu; M^-1 A keeps the springs-only Jacobi's width for any kappa when Q = T^-1
// (docs/benchmarks.md, "Any Poisson ratio", parts 4-5). One step costs a ghost exchange and two passes over the
// cells; each further step another exchange and two passes.
#pragma once
#include <petscksp.h>

#include "partition/local_model.hpp"
#include "src/physics/force_model.hpp"

namespace tissue {

// Chebyshev steps on the lattice multigrid's coarse levels (all but the finest and the coarsest) when some cell
// has a volumetric part (k > 0) and is near cubic (its edges within kCellCoarseAspect of each other):
// -static_cell_coarse_steps S overrides (0: the levels' default, 2).
inline constexpr int kCellCoarseSteps = 4;
inline constexpr double kCellCoarseAspect = 1.25;

// Collective. When the force model has a term with a volume coupling (the cell term) on some rank: sets the coarse
// levels' Chebyshev steps (above); when the option -static_volume_smoother is on too (or, absent, `by_default`),
// makes the PC of pc's finest level (a PCMG) a PCSHELL applying the Woodbury smoother above;
// -static_volume_smoother_steps m (default 1) sets Q's steps. The level's KSP (Chebyshev) and its -mg_levels_*
// options stay; -mg_levels_pc_type replaces the shell.
PetscErrorCode use_volume_smoother(const LocalModel& model, const ForceModel& forces, PC pc, bool by_default);

// For the test: the smoother as a PCSHELL on A (a matrix with A's diagonal from MatGetDiagonal, 3 unknowns a
// molecule in owned order), from the given cells (Term::VolumeCoupling) and held components (3 * local).
PetscErrorCode make_volume_smoother(const LocalModel& model, const std::vector<std::uint8_t>& held,
                                    Term::VolumeCoupling cells, int steps, PC pc);

}  // namespace tissue
