// The matrix-free finest level's smoother: PETSc's Chebyshev iteration on Jacobi (KSPCHEBYSHEV with PCJACOBI, first
// kind, fixed eigenvalue bounds) with its vector operations fused. Per step PETSc passes over the level's vectors
// four times after the product (r = b - A p, z = D^-1 r, the three-term update, and a copy or set), each pass
// reading two or three 24 B-a-molecule arrays; here each step is the product and one pass over the rows, which
// computes the same numbers (the same operations on every component, in the same order: the result is PETSc's to
// the bit) from b, A p, D^-1 and the last two iterates. Two work vectors for two steps (PETSc keeps three).
// KSPChebyshevSetEigenvalues sets its interval as it sets KSPCHEBYSHEV's (the Gershgorin bound of the matrix-free
// finest level: newton_equilibrium.cpp); fused_chebyshev_estimate has it estimate the interval as KSPCHEBYSHEV with
// KSPChebyshevEstEigSet does (a term adds blocks: the cells), by PETSc's own estimator whenever the operator changed.
#pragma once
#include <petscksp.h>

namespace tissue {

// The KSP type's name (registered once, by register_fused_chebyshev).
inline constexpr const char* kFusedChebyshev = "tissue_fused_chebyshev";
// Not collective. Registers the type with PETSc (idempotent).
PetscErrorCode register_fused_chebyshev();
// Not collective. The interval from PETSc's estimate whenever the operator changes: KSPChebyshevEstEigSet(a, b, c,
// d) on a KSPCHEBYSHEV over PCJACOBI with the same operators, its estimator CG of `steps` iterations, set up (the
// estimate: PETSc's noisy right-hand side) and then read (KSPComputeEigenvalues), so that the interval, and every
// smoothing after it, are those of PETSc's KSPCHEBYSHEV so configured, to the bit. The estimator's vectors live
// only during the estimate.
PetscErrorCode fused_chebyshev_estimate(KSP ksp, PetscReal a, PetscReal b, PetscReal c, PetscReal d, PetscInt steps);
// Fills vecs (up to max) with vectors whose values nobody needs while the smoother is set up; *count of them.
using IdleVectors = PetscErrorCode (*)(void* ctx, PetscInt max, PetscInt* count, Vec* vecs);
// Not collective. When an estimate runs, `idle` is asked for such vectors (the outer Krylov method's work vectors
// before its iterations, the level's own); the estimate's work vectors (PETSc's estimator makes six of the level's
// size, each first touched for it alone) are placed on the arrays of those of the level's size, the rest made as
// before. Every number is the same (the same vector type and operations, on other memory).
PetscErrorCode fused_chebyshev_idle(KSP ksp, IdleVectors idle, void* ctx);

}  // namespace tissue
