// Geometric multigrid on the molecule lattice: every body is a box lattice, so each coarser level keeps every
// other lattice plane of the level below (the last plane always), and the interpolation is trilinear in the
// lattice indices, the same weight for the three components. Coarse operators are Galerkin products (PCMG
// with PC_MG_GALERKIN_BOTH), so every topology, calibration and contact term is coarsened consistently, and
// trilinear interpolation reproduces the rigid-body modes (linear fields) exactly. Compared with GAMG's smoothed
// aggregation its prolongators are 3-8 entries a row (no graph, no coarsening, no prolongator smoothing), so the
// set-up is a fraction of GAMG's and the coarse operators stay 27-point stencils. Held components get no
// coarse correction (their rows of the finest interpolation are empty).
#pragma once
#include <petscpc.h>

#include <cstdint>
#include <vector>

#include "partition/local_model.hpp"

namespace tissue {

// Collective. Makes pc a PCMG with the lattice hierarchy (coarsest level at most about coarse_nodes molecules,
// solved by PCMG's default redundant LU). levels = number of levels built (1: the lattice is already that small
// and pc is left untouched; also for a scene with an explicit topology, which has no lattice).
PetscErrorCode setup_lattice_mg(const LocalModel& model, const std::vector<std::uint8_t>& held, PC pc,
                                long coarse_nodes, PetscInt* levels);

}  // namespace tissue
