// Geometric multigrid on the molecule lattice: every body is a box lattice, so each coarser level keeps every
// other lattice plane of the level below (the last plane always), and the interpolation is trilinear in the
// lattice indices, the same weight for the three components. Coarse operators are Galerkin products (PCMG
// with PC_MG_GALERKIN_BOTH), so every topology, calibration and contact term is coarsened consistently, and
// trilinear interpolation reproduces the rigid-body modes (linear fields) exactly. Compared with GAMG's smoothed
// aggregation its prolongators are 3-8 entries a row (no graph, no coarsening, no prolongator smoothing), so the
// set-up is a fraction of GAMG's and the coarse operators stay 27-point stencils. Held components get no
// coarse correction (their rows of the finest interpolation are empty).
#pragma once
#include <petscksp.h>

#include <array>
#include <cstdint>
#include <vector>

#include "partition/local_model.hpp"

namespace tissue {

// The hierarchy as built, level 0 the finest: what the structured Galerkin product (lattice_galerkin.hpp) needs.
struct LatticeLevels {
  using Planes = std::vector<std::array<std::vector<long>, 3>>;  // [body][axis]: the lattice planes kept
  std::vector<Planes> planes;
  std::vector<std::vector<int>> owned_nodes;  // this rank's nodes (local molecule indices, owned order)
  std::vector<std::vector<PetscInt>> base;    // the global number of each node's first unknown
  std::vector<PetscInt> first, count;         // this rank's first unknown and number of unknowns
  // named[l] (l >= 1): how many distinct level-l nodes this rank's level l-1 nodes with a free component
  // interpolate from (the rows the structured Galerkin product sums into here, before the rows of other ranks'
  // nodes go to their owners).
  std::vector<std::size_t> named;
};

// Where lattice plane x sits among a coarser level's planes (sorted, containing the first and last plane): on
// plane at[0] (n = 1, weight 1) or between planes at[0] and at[1] (n = 2, linear weights); at indexes `coarse`.
// The interpolation and the structured Galerkin product (lattice_galerkin.cpp) both take their weights here.
struct PlaneWeights {
  int n = 0;
  std::array<int, 2> at{};
  std::array<double, 2> w{};
};
PlaneWeights plane_weights(const std::vector<long>& coarse, long x);

// Collective. Makes pc a PCMG with the lattice hierarchy (coarsest level at most about coarse_nodes molecules,
// solved by PCMG's default redundant LU), Galerkin coarse operators. levels = number of levels built (1: the
// lattice is already that small, or a body is a mesh or random cloud, and pc is left untouched). hierarchy, when
// given and levels > 1, receives the levels' planes and numbering. finest_as_shell: the finest interpolation is a
// shell (lattice_interpolation.hpp: no AIJ matrix), for coarse operators that are not PCMG's Galerkin products
// (the matrix-free solve's; the caller sets PC_MG_GALERKIN_NONE and the operators).
PetscErrorCode setup_lattice_mg(const LocalModel& model, const std::vector<std::uint8_t>& held, PC pc,
                                long coarse_nodes, PetscInt* levels, LatticeLevels* hierarchy = nullptr,
                                bool finest_as_shell = false);

// A level's Chebyshev smoother estimates its eigenvalue interval as [0.1, 1.1] x the largest eigenvalue a short CG
// run finds (what setup_lattice_mg sets on every level; the matrix-free finest level may set bounds instead).
PetscErrorCode estimate_chebyshev_interval(KSP smoother);
// Its transform (KSPChebyshevEstEigSet's a, b, c, d) and the estimator CG's iterations (the fused finest smoother
// estimates with the same: fused_chebyshev_estimate).
inline constexpr PetscReal kChebyshevEstimate[4] = {0, 0.1, 0, 1.1};
inline constexpr PetscInt kChebyshevEstimateSteps = 6;

// Collective. The numbers `answers` of molecules (global ids `asked`), from their owners' (ids `mine`, numbers
// `nums`), through a directory: id g lives on rank g / chunk, so no rank holds more than its chunk of it.
PetscErrorCode lattice_lookup(MPI_Comm comm, std::int64_t total, const std::vector<std::int64_t>& mine,
                              const std::vector<PetscInt>& nums, const std::vector<std::int64_t>& asked,
                              std::vector<PetscInt>& answers);

}  // namespace tissue
