// The matrix-free finest level's smoother: PETSc's Chebyshev iteration on Jacobi (KSPCHEBYSHEV with PCJACOBI, first
// kind, fixed eigenvalue bounds) with its vector operations fused. Per step PETSc passes over the level's vectors
// four times after the product (r = b - A p, z = D^-1 r, the three-term update, and a copy or set), each pass
// reading two or three 24 B-a-molecule arrays; here each step is the product and one pass over the rows, which
// computes the same numbers (the same operations on every component, in the same order: the result is PETSc's to
// the bit) from b, A p, D^-1 and the last two iterates. Two work vectors for two steps (PETSc keeps three).
// KSPChebyshevSetEigenvalues sets its interval as it sets KSPCHEBYSHEV's; there is no estimator, so it serves
// only where the bounds are known (the Gershgorin bound of the matrix-free finest level: newton_equilibrium.cpp).
#pragma once
#include <petscksp.h>

namespace tissue {

// The KSP type's name (registered once, by register_fused_chebyshev).
inline constexpr const char* kFusedChebyshev = "tissue_fused_chebyshev";
// Not collective. Registers the type with PETSc (idempotent).
PetscErrorCode register_fused_chebyshev();

}  // namespace tissue
