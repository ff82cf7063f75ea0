// The Newton equilibrium solve behind the static and quasi-static solvers: PETSc SNES Newton on the geometrically
// exact spring forces, with the assembled tangent stiffness (material and geometric parts, AIJ block size 3, held
// components eliminated so it stays symmetric). Defaults: Newton with a backtracking line search, CG
// preconditioned by the lattice's geometric multigrid (lattice_mg.hpp; GAMG with the rigid-body near-null space on
// -pc_type gamg, for tiny lattices and as fall-back), the lattice multigrid reused across Newton iterations, load
// steps and time steps; every choice can be changed from the PETSc options database (tissue run s.toml --
// -ksp_type gmres -pc_type hypre -snes_monitor -log_view). Large loads are applied in load increments, and an
// increment that fails is cut in half (up to 8 times). A tangent found indefinite (compressed springs) switches
// the Krylov method to GMRES, with a message.
#include <petsc/private/kspimpl.h>  // the finest smoother's work vectors, lent to the line search
#include <petscsnes.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>
#include <utility>

#include "src/solvers/fused_chebyshev.hpp"
#include "src/solvers/guards.hpp"
#include "src/solvers/lattice_galerkin.hpp"
#include "src/solvers/lattice_mg.hpp"
#include "src/solvers/matrix_free.hpp"
#include "src/solvers/petsc_errors.hpp"
#include "src/solvers/rest_tangent.hpp"
#include "src/solvers/volume_smoother.hpp"
#include "src/solvers/molecule_report.hpp"
#include "src/solvers/newton_equilibrium.hpp"
#include "src/solvers/solver.hpp"

namespace tissue {

namespace {

// The energy line search (cp) keeps the full Newton step when the energy slope along it at lambda = 1 is below
// this fraction of the slope at lambda = 0 (SNESLineSearchSetTolerances' rtol; -snes_linesearch_rtol wins).
constexpr double kFullStepSlope = 1e-3;
constexpr double kFirstRtol = 1e-4;  // Krylov tolerance of a load step's first Newton step (see NewtonEquilibrium::setup)
// A later Newton step's Krylov solve may leave this share of the Newton tolerance minus the step's predicted
// nonlinear remainder (before_newton_step; at least Context::enough_fraction of the tolerance).
constexpr double kEnoughShare = 0.5;

struct Context {
  const LocalModel* model;
  const ForceModel* forces;
  SolverState* state;
  double load_factor;
  const SolverHooks* hooks;
  // Krylov tolerance of the first Newton step of each load step and of the later ones (first_rtol 0: no change).
  double first_rtol = 0.0, rtol = 1e-10;
  // Above 0: the first Newton step's Krylov tolerance is this fraction of what takes the residual from its start
  // to the Newton tolerance, within [rtol, kFirstRtol] (NewtonEquilibrium::target_first_krylov).
  double targeted = 0.0;
  // Above 0 (with the forcing above): a later Newton step's Krylov solve also stops once CG's residual, in the
  // force norm SNES tests, is below this fraction of the Newton tolerance (see converged_or_enough).
  double enough_fraction = 0.1;
  double enough = 0.0;  // that bound in N for the current Newton step (0: not this step)
  double previous_norm = 0.0;  // the residual norm at the start of the last Newton step (before_newton_step)
  double enough_share = kEnoughShare;  // -static_enough_share S (0: the fixed fraction alone)
  // The lattice multigrid's coarse operators from the lattice structure (null: PCMG's own Galerkin product).
  LatticeGalerkin* galerkin = nullptr;
  // The matrix-free tangent (solver.operator = "matrix-free"): J is its shell, and no fine matrix exists.
  MatrixFreeTangent* shell = nullptr;
  // The finest level's operator at rest (rest_tangent.hpp; null: J, as PCMG takes it).
  RestTangent* rest = nullptr;
  // The matrix-free finest level's Chebyshev interval from Gershgorin's bound (fine_chebyshev), and the lower end
  // as a fraction of the upper (-static_chebyshev_fraction).
  bool gershgorin = false, estimating = true;
  bool fused_estimating = false;  // the finest smoother is the fused one with PETSc's estimate (a term's blocks)
  // With that interval, the finest smoother is PETSc's Chebyshev-Jacobi with its vector operations fused
  // (fused_chebyshev.hpp: the same numbers; -static_fused_chebyshev false keeps PETSc's KSPCHEBYSHEV).
  bool fused = true;
  // 0.2: on the peer problem at 97,336 molecules the Krylov iterations of the estimate's [0.1, 1.1] x lambda
  // (15) with 0.15 and 0.2; 16 with 0.1 and 0.3, 17 with 0.05 (the bound exceeds lambda_max by about 1.3x).
  double chebyshev_fraction = 0.2;
  // With a term's blocks: the finest interval's upper end as a multiple of the interior symbol's largest eigenvalue
  // (LatticeGalerkin::symbol_bound; -static_symbol_upper U, 0: PETSc's estimate), its lower end kSymbolFraction
  // of it (fine_chebyshev).
  double symbol_upper = 1.15;
  // The last residual evaluation (residual()): the output vector's id and state just after it was written, and the
  // load factor; valid within one SNESSolve, until the next Newton step (see same_as_last).
  bool reuse = true;  // -static_reuse_residual false: evaluate every time
  bool last_valid = false;
  PetscObjectId last_id = 0;
  PetscObjectState last_state = 0;
  double last_load = 0.0;
  KSP krylov = nullptr;  // the outer Krylov solve's (idle_vectors; null with -static_estimate_on_idle false)
  // What a callback threw on this rank. An exception must not cross PETSc's C frames, and this rank must not leave
  // SNES while the others go on in its collectives: the callback keeps it, SNES ends the solve on every rank
  // (see residual()), and the ranks agree on it after SNESSolve.
  std::exception_ptr error = nullptr;
};

// Preconditioner reuse. The multigrid set-up (Galerkin products) costs several Krylov solves, and at the strains
// of a tissue test the tangent hardly changes between Newton iterations and load steps, so the lattice
// multigrid is built once (SNES preconditioner lag -1, persisting across solves) and rebuilt, on the next
// tangent, only when a linear solve takes more than twice the iterations (plus 10) of the first solve after
// the last rebuild, or fails. GAMG gets the same reuse on large meshes and random clouds at 2+ ranks (see
// kGamgReuseMolecules), where its all-at-once Galerkin products would otherwise be redone every Newton iteration.
// Elsewhere GAMG is rebuilt every iteration as before: on the small, mechanism-prone lattices it serves
// (rectangular topology) a stale GAMG took 149 iterations instead of 16 and moved an unloaded body by 3e-14 m
// where the test allows 1e-14. Off when the user sets -snes_lag_preconditioner (-snes_lag_preconditioner -2
// -snes_lag_preconditioner_persists gives GAMG the same reuse).
struct Reuse {
  bool active = false;
  bool fresh = true;    // the next linear solve uses a freshly built preconditioner
  PetscInt fresh_its = 0;
  long rebuilds = 0;
};

PetscErrorCode rebuild_next(SNES snes, Reuse* reuse) {
  PetscFunctionBeginUser;
  PetscCall(SNESSetLagPreconditioner(snes, -2));  // -2: rebuild once at the next tangent, then lag -1 again
  reuse->fresh = true;
  PetscFunctionReturn(0);
}

// SNES monitor (called after every Newton iteration's linear solve): watches the Krylov iterations.
PetscErrorCode watch_reuse(SNES snes, PetscInt it, PetscReal, void* p) {
  PetscFunctionBeginUser;
  auto* reuse = static_cast<Reuse*>(p);
  if (!reuse->active || it == 0) PetscFunctionReturn(0);
  KSP ksp;
  PetscInt its;
  PetscCall(SNESGetKSP(snes, &ksp));
  PetscCall(KSPGetIterationNumber(ksp, &its));
  if (reuse->fresh) {
    reuse->fresh = false, reuse->fresh_its = its;
  } else if (its > 2 * reuse->fresh_its + 10) {
    reuse->rebuilds++;
    PetscCall(rebuild_next(snes, reuse));
  }
  PetscFunctionReturn(0);
}

// Copies the owned values of X into the state's positions and refreshes the ghosts.
PetscErrorCode load_positions(Context* ctx, Vec X) {
  PetscFunctionBeginUser;
  const PetscScalar* xs;
  PetscCall(VecGetArrayRead(X, &xs));
  std::memcpy(ctx->state->x.array(), xs, sizeof(double) * 3 * ctx->model->owned);
  PetscCall(VecRestoreArrayRead(X, &xs));
  ctx->state->x.update_ghosts();
  PetscFunctionReturn(0);
}

// The state's forces at the positions X (state.f, held components zero); a failure is kept in ctx->error.
PetscErrorCode evaluate_forces(Context* ctx, Vec X) {
  PetscFunctionBeginUser;
  PetscCall(load_positions(ctx, X));
  // Called on every evaluation even after a failure, so that the ranks make the same collectives (contact terms
  // exchange inside forces()); the first error is kept.
  const std::exception_ptr error = attempt([&] {
    fault_point("static", ctx->model->comm);
    ctx->forces->forces(ctx->state->x.array(), ctx->state->v.data(), ctx->state->f.data(), ctx->load_factor);
  });
  if (!ctx->error) ctx->error = error;
  PetscFunctionReturn(0);
}

// Whether R still holds the last evaluation's residual at X on every rank (agreed): the same output vector, not
// written since, the same load factor, no failure, and X the positions evaluated, to the bit. The cp line search
// (the cells' energy line search) evaluates at lambda = 1 for its secant step and then again at the lambda it
// takes; where that is 1 (a Newton step that lands on the solution) the second evaluation is the first's point.
PetscErrorCode same_as_last(Context* ctx, Vec X, Vec R, bool* same) {
  PetscFunctionBeginUser;
  *same = false;
  if (!ctx->reuse || !ctx->last_valid) PetscFunctionReturn(0);  // alike on every rank (the same evaluations)
  PetscObjectId id;
  PetscObjectState state;
  PetscCall(PetscObjectGetId(reinterpret_cast<PetscObject>(R), &id));
  PetscCall(PetscObjectStateGet(reinterpret_cast<PetscObject>(R), &state));
  int here = !ctx->error && id == ctx->last_id && state == ctx->last_state && ctx->load_factor == ctx->last_load;
  if (here) {
    const PetscScalar* xs;
    PetscCall(VecGetArrayRead(X, &xs));
    here = std::memcmp(xs, ctx->state->x.array(), sizeof(double) * 3 * ctx->model->owned) == 0;
    PetscCall(VecRestoreArrayRead(X, &xs));
  }
  int everywhere = 0;
  PetscCallMPI(MPI_Allreduce(&here, &everywhere, 1, MPI_INT, MPI_MIN, ctx->model->comm));
  *same = everywhere != 0;
  PetscFunctionReturn(0);
}

// R(x) = -(connection forces + applied forces), zero on held components: SNES drives it to zero.
PetscErrorCode residual(SNES, Vec X, Vec R, void* p) {
  PetscFunctionBeginUser;
  auto* ctx = static_cast<Context*>(p);
  bool same = false;
  PetscCall(same_as_last(ctx, X, R, &same));
  ctx->last_valid = false;
  if (same) {
    // The evaluation's result is R already (the positions and their ghosts are in the state); the state's forces,
    // which the products use as scratch, are R's negation again (exact, zeros' signs included). The fault point
    // counts it as an evaluation.
    const std::exception_ptr error = attempt([&] { fault_point("static", ctx->model->comm); });
    if (!error) {
      const PetscScalar* r;
      PetscCall(VecGetArrayRead(R, &r));
      for (int i = 0; i < 3 * ctx->model->owned; ++i) ctx->state->f[i] = -r[i];
      PetscCall(VecRestoreArrayRead(R, &r));
      ctx->last_valid = true;  // R and its state are unchanged
      PetscCall(PetscInfo(nullptr, "static: the residual at the last evaluation's positions kept\n"));
      PetscFunctionReturn(0);
    }
    ctx->error = error;  // R gets the NaN below
  } else {
    PetscCall(evaluate_forces(ctx, X));
  }
  PetscScalar* r;
  PetscCall(VecGetArray(R, &r));
  // A rank whose evaluation failed hands SNES a NaN residual: its norm is NaN on every rank, so every rank's SNES
  // stops at this iteration (DIVERGED_FNORM_NAN) and reaches the agreement after SNESSolve together.
  for (int i = 0; i < 3 * ctx->model->owned; ++i) r[i] = ctx->error ? NAN : -ctx->state->f[i];
  PetscCall(VecRestoreArray(R, &r));
  PetscCall(PetscObjectGetId(reinterpret_cast<PetscObject>(R), &ctx->last_id));
  PetscCall(PetscObjectStateGet(reinterpret_cast<PetscObject>(R), &ctx->last_state));
  ctx->last_load = ctx->load_factor;
  ctx->last_valid = true;
  PetscFunctionReturn(0);
}

// SNES update, at the start of every Newton iteration: a calibration that follows the deformation (angles-update)
// refreshes the stiffness from the current iterate, and the Krylov tolerance is set for this step.
PetscErrorCode before_newton_step(SNES snes, PetscInt step) {
  PetscFunctionBeginUser;
  void* p;
  PetscCall(SNESGetApplicationContext(snes, &p));
  auto* ctx = static_cast<Context*>(p);
  ctx->last_valid = false;  // a refresh below changes the forces at the same positions
  if (ctx->hooks->refresh) {
    Vec X;
    PetscCall(SNESGetSolution(snes, &X));
    PetscCall(load_positions(ctx, X));
    const std::exception_ptr error = attempt([&] { ctx->hooks->refresh(ctx->state->x.array()); });
    if (!ctx->error) ctx->error = error;
  }
  if (ctx->first_rtol > 0 || ctx->targeted > 0) {
    double rtol = step == 0 && ctx->first_rtol > 0 ? ctx->first_rtol : ctx->rtol;
    if (step == 0 && ctx->targeted > 0) {
      PetscReal start, atol;
      PetscCall(SNESGetFunctionNorm(snes, &start));
      PetscCall(SNESGetTolerances(snes, &atol, nullptr, nullptr, nullptr, nullptr));
      if (start > 0) rtol = std::clamp(ctx->targeted * atol / start, ctx->rtol, kFirstRtol);
    }
    KSP ksp;
    PetscCall(SNESGetKSP(snes, &ksp));
    PetscCall(KSPSetTolerances(ksp, rtol, PETSC_DEFAULT, PETSC_DEFAULT, 10000));
    ctx->enough = 0.0;
    PetscReal now;
    PetscCall(SNESGetFunctionNorm(snes, &now));
    if (step > 0 && ctx->enough_fraction > 0) {
      PetscReal atol;
      PetscCall(SNESGetTolerances(snes, &atol, nullptr, nullptr, nullptr, nullptr));
      // The step's nonlinear remainder predicted from the last step's quadratic constant, K = r_k / r_(k-1)^2,
      // as K r_k^2 (an overestimate while the last step's linear residual was part of r_k): the solve may leave
      // kEnoughShare of what the Newton tolerance has room for beyond it, and never less than the fixed fraction.
      double fraction = ctx->enough_fraction;
      if (ctx->enough_share > 0 && ctx->previous_norm > 0 && now > 0) {
        const double ratio = now / ctx->previous_norm, remainder = now * ratio * ratio;
        fraction = std::max(fraction, ctx->enough_share * (1.0 - remainder / atol));
      }
      ctx->enough = fraction * atol;
    }
    ctx->previous_norm = now;
  }
  PetscFunctionReturn(0);
}

// The Krylov convergence test with the forcing: PETSc's default test (the relative tolerance on the preconditioned
// norm), and in the Newton steps after the first also a stop once CG's residual r = F + J dx is below
// Context::enough in the force norm. Solving further is wasted: the next residual SNES sees is r plus the
// nonlinear remainder of the step, and the 1e-10 relative tolerance on the preconditioned norm took that linear
// residual ~1000x below the remainder (docs/benchmarks.md, static18j). The bound keeps the next residual within the Newton tolerance whenever
// the remainder is below 0.9 of it, so the Newton count does not change. r is CG's own recursive residual
// (KSPSolve_CG's work[0]): one norm, no product; every rank decides on the same global norm.
struct KrylovTest {
  Context* ctx;
  void* default_test = nullptr;
};

PetscErrorCode converged_or_enough(KSP ksp, PetscInt it, PetscReal rnorm, KSPConvergedReason* reason, void* p) {
  PetscFunctionBeginUser;
  auto* test = static_cast<KrylovTest*>(p);
  PetscCall(KSPConvergedDefault(ksp, it, rnorm, reason, test->default_test));
  if (*reason != KSP_CONVERGED_ITERATING || test->ctx->enough <= 0 || ksp->nwork < 1) PetscFunctionReturn(0);
  PetscBool cg = PETSC_FALSE;
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(ksp), KSPCG, &cg));
  if (!cg) PetscFunctionReturn(0);
  PetscReal norm;
  PetscCall(VecNorm(ksp->work[0], NORM_2, &norm));
  if (norm <= test->ctx->enough) *reason = KSP_CONVERGED_ATOL;
  PetscFunctionReturn(0);
}

PetscErrorCode destroy_krylov_test(void* p) {
  PetscFunctionBeginUser;
  auto* test = static_cast<KrylovTest*>(p);
  PetscCall(KSPConvergedDefaultDestroy(test->default_test));
  delete test;
  PetscFunctionReturn(0);
}

// The matrix-free solve's line search works in two of the finest Chebyshev smoother's work vectors instead of two
// of its own (48 B a molecule): the smoother uses them only inside the linear solve, the line search only after
// it (its trial positions and their residual; its slope's product J Y also goes to the first). Lent once, after
// the first linear solve (KSP post-solve: the smoother exists then, the line search has not yet made its own);
// the line search holds a reference, so they outlive a smoother rebuilt or replaced (the GAMG fall-back).
PetscErrorCode lend_smoother_vectors(KSP ksp, Vec, Vec, void* p) {
  PetscFunctionBeginUser;
  auto* snes = static_cast<SNES*>(p);
  if (!*snes) PetscFunctionReturn(0);
  SNESLineSearch line_search;
  Vec W = nullptr, G = nullptr;
  PetscCall(SNESGetLineSearch(*snes, &line_search));
  PetscCall(SNESLineSearchGetVecs(line_search, nullptr, nullptr, nullptr, &W, &G));
  PC pc;
  PetscBool mg = PETSC_FALSE, chebyshev = PETSC_FALSE;
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(pc), PCMG, &mg));
  if (W || G || !mg) {
    *snes = nullptr;  // once
    PetscFunctionReturn(0);
  }
  PetscInt levels;
  KSP smoother;
  PetscCall(PCMGGetLevels(pc, &levels));
  PetscCall(PCMGGetSmoother(pc, levels - 1, &smoother));
  PetscCall(PetscObjectTypeCompareAny(reinterpret_cast<PetscObject>(smoother), &chebyshev, KSPCHEBYSHEV,
                                      kFusedChebyshev, ""));
  if (chebyshev && smoother->nwork >= 2) {
    PetscCall(PetscObjectReference(reinterpret_cast<PetscObject>(smoother->work[0])));
    PetscCall(PetscObjectReference(reinterpret_cast<PetscObject>(smoother->work[1])));
    PetscCall(SNESLineSearchSetVecs(line_search, nullptr, nullptr, nullptr, smoother->work[0], smoother->work[1]));
  }
  *snes = nullptr;
  PetscFunctionReturn(0);
}

// The preconditioner is rebuilt after this tangent exactly when the lag is -2 (see Reuse); pc: SNES's.
PetscErrorCode rebuild_pending(SNES snes, PC* pc, bool* rebuild) {
  PetscFunctionBeginUser;
  PetscInt lag;
  KSP ksp;
  PetscCall(SNESGetLagPreconditioner(snes, &lag));
  PetscCall(SNESGetKSP(snes, &ksp));
  PetscCall(KSPGetPC(ksp, pc));
  *rebuild = lag == -2;
  PetscFunctionReturn(0);
}

// The levels between the finest and the coarsest: PETSc's Chebyshev-Jacobi with its estimate (setup_lattice_mg's)
// becomes the fused one estimating the same way (fused_chebyshev.hpp: the same numbers to the bit), so that each
// step is the product and one pass over the level's vectors instead of four. With the cells a level's call is 4
// steps (use_volume_smoother) over vectors too large for the cache at 10^6 (level 1: 3 MB each). Once: a level
// already fused keeps its estimate's state (it estimates again when its operator changes, as PETSc's does).
PetscErrorCode fuse_coarse_chebyshev(PC pc, PetscInt levels) {
  PetscFunctionBeginUser;
  for (PetscInt l = 1; l + 1 < levels; ++l) {
    KSP smoother;
    PetscBool chebyshev = PETSC_FALSE;
    PetscCall(PCMGGetSmoother(pc, l, &smoother));
    PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(smoother), KSPCHEBYSHEV, &chebyshev));
    if (!chebyshev) continue;
    // A level's own smoother options (-mg_levels_N_...; the ones for every level keep all of them PETSc's, see
    // use_matrix_free) keep that level PETSc's.
    PetscBool own = PETSC_FALSE;
    for (const char* option : {"ksp_type", "pc_type", "ksp_chebyshev_eigenvalues", "ksp_chebyshev_esteig",
                               "esteig_ksp_type", "esteig_ksp_max_it", "ksp_chebyshev_kind",
                               "ksp_chebyshev_esteig_noisy", "pc_jacobi_type", "pc_jacobi_abs"}) {
      const std::string name = "-mg_levels_" + std::to_string(l) + "_" + option;
      PetscBool has = PETSC_FALSE;
      PetscCall(PetscOptionsHasName(nullptr, nullptr, name.c_str(), &has));
      own = own || has ? PETSC_TRUE : PETSC_FALSE;
    }
    if (own) continue;
    PC jacobi;
    PetscCall(register_fused_chebyshev());
    PetscCall(KSPSetType(smoother, kFusedChebyshev));
    PetscCall(KSPGetPC(smoother, &jacobi));
    PetscCall(PCSetType(jacobi, PCNONE));  // its own D^-1
    PetscCall(fused_chebyshev_estimate(smoother, kChebyshevEstimate[0], kChebyshevEstimate[1], kChebyshevEstimate[2],
                                       kChebyshevEstimate[3], kChebyshevEstimateSteps));
  }
  PetscFunctionReturn(0);
}

// The vectors idle while the multigrid is set up (fused_chebyshev_idle, for the finest level's estimate): the outer
// CG's work vectors (PCSetUp runs inside its KSPSetUp, after they are made and before its iterations) and the
// finest smoother's (PCMG's finest residual among them), which the smoothing and, after the linear solve, the line
// search use.
PetscErrorCode idle_vectors(void* p, PetscInt max, PetscInt* count, Vec* vecs) {
  PetscFunctionBeginUser;
  auto* ctx = static_cast<Context*>(p);
  *count = 0;
  PetscBool cg = PETSC_FALSE;
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(ctx->krylov), KSPCG, &cg));
  if (cg)
    for (PetscInt i = 0; i < ctx->krylov->nwork && *count < max; ++i) vecs[(*count)++] = ctx->krylov->work[i];
  PC pc;
  PetscInt levels;
  KSP smoother;
  PetscCall(KSPGetPC(ctx->krylov, &pc));
  PetscCall(PCMGGetLevels(pc, &levels));
  PetscCall(PCMGGetSmoother(pc, levels - 1, &smoother));
  for (PetscInt i = 0; i < smoother->nwork && *count < max; ++i) vecs[(*count)++] = smoother->work[i];
  PetscFunctionReturn(0);
}

// The finest level's Chebyshev interval [f G, G] from Gershgorin's bound G on the Jacobi-scaled tangent
// (ForceModel::jacobi_gershgorin, one pass over the connections, no storage) instead of PETSc's estimate: no
// estimator CG on the finest level (its work vectors, 4 a molecule, and 6 products at every rebuild). Where the
// bound is not exact (a term adds blocks) the estimate as on the coarser levels.
constexpr double kSymbolFraction = 0.1 / 1.1;  // the estimate's [0.1, 1.1]: the same lower end a symbol's upper
PetscErrorCode fine_chebyshev(Context* ctx, PC pc) {
  PetscFunctionBeginUser;
  PetscInt levels;
  KSP smoother;
  PetscCall(PCMGGetLevels(pc, &levels));
  if (ctx->fused) PetscCall(fuse_coarse_chebyshev(pc, levels));
  PetscCall(PCMGGetSmoother(pc, levels - 1, &smoother));
  double bound = 0.0;
  bool exact = false;
  if (!ctx->forces->has_terms() && !ctx->forces->has_cached_tangent()) {
    bound = ctx->galerkin->jacobi_bound();  // summed from the coarse operators' block stream just now (no 2nd pass)
    exact = true;
  } else {
    PetscCall(ctx->forces->jacobi_gershgorin(ctx->shell->positions(), &bound, &exact));
  }
  PC jacobi;
  PetscCall(KSPGetPC(smoother, &jacobi));
  double fraction = ctx->chebyshev_fraction;
  const double symbol = ctx->galerkin->symbol_bound();
  if (!exact && ctx->symbol_upper > 0.0 && symbol > 0.0) {
    // A term's blocks (the cell term): the interval [0.1 / 1.1, 1] x 1.15 x the interior rows' symbol's largest
    // eigenvalue instead of PETSc's estimate (6 CG steps with the term's product, and their vectors). That
    // estimate lands just under the symbol's value (4.37 against 4.40 at nu = 0.45), at the edge of a cliff: the
    // Krylov count at 60^3 is flat for an upper end of 1.1-1.2 x the symbol at nu = 0.3, 0.45 and 0.49 and
    // rises steeply below it (0.45: 22 at 1.05, 41 at 0.91); 1.15 is the middle (docs/poisson.md).
    bound = ctx->symbol_upper * symbol, fraction = kSymbolFraction, exact = true;
  }
  if (exact) {
    if (ctx->fused) {
      PetscCall(register_fused_chebyshev());
      PetscCall(KSPSetType(smoother, kFusedChebyshev));  // its own D^-1: no PCJACOBI beside it
      PetscCall(PCSetType(jacobi, PCNONE));
    } else {
      PetscCall(KSPChebyshevEstEigSet(smoother, 0, 0, 0, 0));  // no estimator (it is destroyed)
    }
    PetscCall(KSPChebyshevSetEigenvalues(smoother, bound, fraction * bound));
    ctx->estimating = false;
  } else if (!ctx->estimating || (ctx->fused && !ctx->fused_estimating)) {
    if (ctx->fused) {
      // The fused steps on the interval PETSc's estimate gives (estimate_chebyshev_interval's, to the bit).
      PetscCall(register_fused_chebyshev());
      PetscCall(KSPSetType(smoother, kFusedChebyshev));
      PetscCall(PCSetType(jacobi, PCNONE));
      PetscCall(fused_chebyshev_estimate(smoother, kChebyshevEstimate[0], kChebyshevEstimate[1],
                                         kChebyshevEstimate[2], kChebyshevEstimate[3], kChebyshevEstimateSteps));
      if (ctx->krylov) PetscCall(fused_chebyshev_idle(smoother, idle_vectors, ctx));
      ctx->fused_estimating = true;
    } else {
      PetscCall(KSPSetType(smoother, KSPCHEBYSHEV));  // the estimate needs PETSc's (a no-op when it is already)
      PetscCall(PCSetType(jacobi, PCJACOBI));
      PetscCall(estimate_chebyshev_interval(smoother));
    }
    ctx->estimating = true;
  }
  PetscFunctionReturn(0);
}

// PCMG's finest residual r (PCSetUp_MG would make one of its own, 24 B a molecule) is the first of the fused
// finest smoother's work vectors, both made here before the first set-up: the smoother uses them only inside its
// own solve, PCMG's r lives from the residual after the pre-smoothing to its restriction (the line search, which
// borrows the same two, only after the linear solve). Nothing when the smoother has its vectors already (later
// rebuilds), is not the fused one or wants a third (max_it > 2: its set-up then makes its own, r stays apart).
PetscErrorCode share_finest_residual(PC pc, Mat J) {
  PetscFunctionBeginUser;
  PetscInt levels;
  KSP smoother;
  PetscBool fused = PETSC_FALSE;
  PetscCall(PCMGGetLevels(pc, &levels));
  if (levels < 2) PetscFunctionReturn(0);
  PetscCall(PCMGGetSmoother(pc, levels - 1, &smoother));
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(smoother), kFusedChebyshev, &fused));
  if (!fused || smoother->nwork > 0 || smoother->max_it > 2) PetscFunctionReturn(0);
  PetscCall(PetscMalloc1(2, &smoother->work));  // KSP frees them with VecDestroyVecs, as its own
  PetscCall(MatCreateVecs(J, &smoother->work[0], &smoother->work[1]));
  smoother->nwork = 2;
  PetscCall(PCMGSetR(pc, levels - 1, smoother->work[0]));
  PetscFunctionReturn(0);
}

PetscErrorCode tangent(SNES snes, Vec X, Mat J, Mat P, void* p) {
  PetscFunctionBeginUser;
  auto* ctx = static_cast<Context*>(p);
  PetscCall(load_positions(ctx, X));
  if (ctx->shell) {
    // Nothing to assemble: the shell takes the positions, and a rebuilt preconditioner's coarse operators come
    // from the force model's block stream at them (lattice_galerkin.hpp).
    PetscCall(ctx->shell->set_positions(ctx->state->x.array(), J));
    PC pc;
    bool rebuild;
    PetscCall(rebuild_pending(snes, &pc, &rebuild));
    if (rebuild) {
      if (ctx->rest) PetscCall(ctx->rest->use(pc, ctx->shell->positions(), J));
      PetscCall(ctx->galerkin->update(*ctx->forces, ctx->shell->positions(), pc));
      if (ctx->gershgorin) PetscCall(fine_chebyshev(ctx, pc));
      PetscCall(share_finest_residual(pc, J));
      ctx->forces->release_block_rows();  // not needed again before the next rebuild
    }
    PetscFunctionReturn(0);
  }
  // A throw here (before or after the assembly's collectives: not known) is kept for the agreement after
  // SNESSolve; the tangent left may be partial, and the solve's result is discarded by that agreement.
  PetscErrorCode assembled = 0;
  const std::exception_ptr error =
      attempt([&] { assembled = ctx->forces->assemble_tangent(ctx->state->x.array(), P); });
  if (!ctx->error) ctx->error = error;
  PetscCall(assembled);
  if (ctx->galerkin) {
    // The preconditioner is rebuilt after this call exactly when the lag is -2 (see Reuse); then its coarse
    // operators must be this tangent's. -pc_mg_galerkin given by the user hands them back to PCMG.
    PC pc;
    bool rebuild;
    PCMGGalerkinType galerkin;
    PetscCall(rebuild_pending(snes, &pc, &rebuild));
    PetscCall(PCMGGetGalerkin(pc, &galerkin));
    if (rebuild && galerkin == PC_MG_GALERKIN_NONE) PetscCall(ctx->galerkin->update(P, pc));
  }
  if (J != P) {
    PetscCall(MatAssemblyBegin(J, MAT_FINAL_ASSEMBLY));
    PetscCall(MatAssemblyEnd(J, MAT_FINAL_ASSEMBLY));
  }
  PetscFunctionReturn(0);
}

// The rigid-body modes of the rest configuration as J's near-null space: what GAMG needs (six vectors; the
// lattice multigrid does without, so they are made only when GAMG is the preconditioner).
PetscErrorCode attach_rigid_modes(const LocalModel& model, Vec like, Mat J) {
  PetscFunctionBeginUser;
  Vec coords;
  PetscCall(VecDuplicate(like, &coords));
  PetscCall(VecSetBlockSize(coords, 3));
  PetscScalar* c;
  PetscCall(VecGetArray(coords, &c));
  std::copy(model.rest.begin(), model.rest.begin() + 3 * model.owned, c);
  PetscCall(VecRestoreArray(coords, &c));
  MatNullSpace rigid;
  PetscCall(MatNullSpaceCreateRigidBody(coords, &rigid));
  PetscCall(MatSetNearNullSpace(J, rigid));  // J keeps a reference
  PetscCall(MatNullSpaceDestroy(&rigid));
  PetscCall(VecDestroy(&coords));
  PetscFunctionReturn(0);
}

}  // namespace

// GAMG's PtAP algorithm at 2+ ranks (see setup()).
constexpr const char* kGamgPtap = "allatonce_merged";
// From this many molecules on, a mesh's or random cloud's GAMG at 2+ ranks is kept across Newton iterations (see
// Reuse): the all-at-once products that keep its memory low cost more than PETSc's default ones, and done once
// instead of every Newton iteration they cost less in all (docs/benchmarks.md). Smaller bodies keep the rebuild
// every iteration and so their results. -static_gamg_reuse_molecules N sets it (0: every size).
constexpr PetscInt kGamgReuseMolecules = 20000;
// The same large bodies get unsmoothed aggregation (one nonzero a row in each block column of the interpolation):
// its Galerkin products are a fraction of the smoothed ones' in time and memory, for more Krylov iterations
// (docs/benchmarks.md, "GAMG's unsmoothed aggregation"). -pc_gamg_agg_nsmooths N sets it.
constexpr PetscInt kGamgSmooths = 0;

struct NewtonEquilibrium::Impl {
  Impl(const Scene& scene, const LocalModel& model, const ForceModel& forces, SolverState& state,
       const SolverHooks& hooks, SolveReport& report, const char* kind, bool own_reference)
      : scene(scene), model(model), forces(forces), state(state), report(report), kind(kind),
        own_reference(own_reference),
        ctx{&model, &forces, &state, 1.0, &hooks} {}
  ~Impl() {
    restore_velocities();
    // Nothing can be reported from here: the objects are released whatever the errors.
    if (set_ptap) PetscOptionsClearValue(nullptr, "-matptap_via");
    VecDestroy(&saved);
    SNESDestroy(&snes);
    MatDestroy(&J);
    VecDestroy(&X);
  }
  PetscErrorCode setup();
  PetscErrorCode solve(long steps);
  PetscErrorCode finish();
  PetscErrorCode clear_ptap() {
    PetscFunctionBeginUser;
    if (set_ptap) PetscCall(PetscOptionsClearValue(nullptr, "-matptap_via"));
    set_ptap = false;
    PetscFunctionReturn(0);
  }

  const Scene& scene;
  const LocalModel& model;
  const ForceModel& forces;
  SolverState& state;
  SolveReport& report;
  const std::string kind;
  const bool own_reference;
  Context ctx;
  Vec X = nullptr, saved = nullptr;
  Mat J = nullptr;
  SNES snes = nullptr;
  KSP ksp = nullptr;
  PC pc = nullptr;
  bool lattice_mg = false, set_ptap = false, switched = false;
  bool by_default = false;  // matrix-free because solver.operator was not given: no note when it does not apply
  std::unique_ptr<LatticeGalerkin> galerkin;
  std::unique_ptr<MatrixFreeTangent> shell;  // kept to the end once made (PETSc objects may still refer to it)
  std::unique_ptr<RestTangent> rest;          // likewise
  PetscErrorCode use_matrix_free(bool user_pc, bool user_lag, bool user_galerkin, LatticeLevels& hierarchy);
  double reference = 1.0, tolerance = 0.0;
  Reuse reuse;
  bool record = false;  // record_load_steps()
  bool record_pending = false;
  SNES lend_to = nullptr;  // lend_smoother_vectors: the SNES whose line search borrows, until it has  // the last load step's row, written by finish() once the solve's memory is gone
  // release_velocities(): the state's velocities (all zero, read by no term) are freed while the solve's memory is
  // alive and given back, zero, before anything reads them (the history's rows, the final check, a failure).
  bool release_v = false, v_released = false;
  void drop_velocities() {
    if (!release_v || v_released || forces.reads_velocity()) return;
    if (std::any_of(state.v.begin(), state.v.end(), [](double v) { return v != 0.0; })) return;
    std::vector<double>().swap(state.v);
    v_released = true;
  }
  void restore_velocities() {
    if (v_released) state.v.assign(3 * static_cast<std::size_t>(model.owned), 0.0);
    v_released = false;
  }
};

PetscErrorCode NewtonEquilibrium::Impl::setup() {
  PetscFunctionBeginUser;
  PetscCall(VecDuplicate(state.x.global(), &X));
  PetscCall(VecCopy(state.x.global(), X));
  PetscBool user_pc = PETSC_FALSE, user_lag = PETSC_FALSE, user_galerkin = PETSC_FALSE;
  PetscCall(PetscOptionsHasName(nullptr, nullptr, "-pc_type", &user_pc));
  PetscCall(PetscOptionsHasName(nullptr, nullptr, "-snes_lag_preconditioner", &user_lag));
  // -pc_mg_galerkin: PCMG forms the coarse operators as products with the fine matrix, which a shell has not
  PetscCall(PetscOptionsHasName(nullptr, nullptr, "-pc_mg_galerkin", &user_galerkin));
  // The matrix-free tangent is decided once the lattice multigrid is known (use_matrix_free); the assembled one
  // is made here. Not given, it is matrix-free where that was measured never slower and 3.8x smaller (box lattices,
  // springs only: docs/benchmarks.md, "The static solve at 1 kB a molecule"; with terms that apply their own
  // product, the cell term: "The cell term's tangent product on its blocks"), and falls back without a note.
  const std::string& op = scene.solver.tangent_operator;
  const auto& terms = forces.terms();
  by_default = op.empty() && !user_pc && !user_lag && !user_galerkin &&
               std::all_of(terms.begin(), terms.end(), [](const auto& t) { return t->tangent_state_fast(); }) &&
               std::none_of(scene.bodies.begin(), scene.bodies.end(), [](const BodySpec& b) { return b.unstructured(); });
  const bool want_matrix_free = op == "matrix-free" || by_default;
  if (!want_matrix_free) PetscCall(forces.create_tangent(&J));

  PetscCall(SNESCreate(model.comm, &snes));
  PetscCall(SNESSetFunction(snes, nullptr, residual, &ctx));
  if (J) PetscCall(SNESSetJacobian(snes, J, J, tangent, &ctx));
  PetscCall(SNESSetType(snes, SNESNEWTONLS));
  PetscCall(SNESSetApplicationContext(snes, &ctx));
  PetscCall(SNESSetUpdate(snes, before_newton_step));
  PetscCall(SNESGetKSP(snes, &ksp));
  {
    PetscBool idle = PETSC_TRUE;
    PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-static_estimate_on_idle", &idle, nullptr));
    if (idle) ctx.krylov = ksp;
  }
  PetscCall(KSPSetType(ksp, KSPCG));
  PetscCall(KSPGetPC(ksp, &pc));
  // The preconditioner: geometric multigrid on the lattice (lattice_mg.hpp) unless the user names one
  // (-pc_type gamg: smoothed aggregation with the rigid-body near-null space). GAMG also stands in
  // when the lattice is too small to coarsen, and takes over if a solve with the lattice multigrid fails.
  PetscInt mg_levels = 1;
  LatticeLevels hierarchy;
  // The matrix-free solve's coarse operators are summed from the lattice (not PCMG's products), so its finest
  // interpolation can be a shell (lattice_interpolation.hpp: about 115 B a molecule less); made again as a matrix
  // if the matrix-free tangent does not apply (use_matrix_free).
  if (!user_pc)
    PetscCall(setup_lattice_mg(model, forces.held(), pc, 1000, &mg_levels, &hierarchy, want_matrix_free));
  lattice_mg = mg_levels > 1;
  if (want_matrix_free) PetscCall(use_matrix_free(user_pc, user_lag, user_galerkin, hierarchy));
  if (lattice_mg) PetscCall(use_volume_smoother(model, forces, pc, false));  // the cells' volume coupling
  // The coarse operators from the lattice structure (lattice_galerkin.hpp) when the tangent is a lattice stencil
  // and the preconditioner's rebuilds are ours (Reuse): cheaper than hypre's triple product (docs/benchmarks.md).
  if (lattice_mg && !user_lag && !ctx.shell) {
    if (!galerkin) galerkin = std::make_unique<LatticeGalerkin>(model, forces.held(), std::move(hierarchy));
    bool stencil = false;
    PetscCall(galerkin->applies(J, &stencil));
    if (stencil) {
      PetscCall(PCMGSetGalerkin(pc, PC_MG_GALERKIN_NONE));
      ctx.galerkin = galerkin.get();
    } else {
      galerkin.reset();
    }
  }
  // The lattice multigrid's Galerkin products through hypre's triple product: a lower memory peak than PETSc's
  // default (scalable) algorithm, in no more time (docs/benchmarks.md).
  // GAMG's products with hypre gave NaN on a contact test: GAMG's (meshes, random clouds) go by PETSc's
  // all-at-once algorithm instead, whose lower peak (the default kept intermediate products that made each of 3
  // ranks need as much memory for the solve as 1 rank did) gives the same numbers (#21, docs/benchmarks.md); on
  // large bodies it is kept across Newton iterations (kGamgReuseMolecules) and aggregates unsmoothed
  // (kGamgSmooths), which keeps its products small.
  // The option is global, so it is set only for this solve and only for our choice of preconditioner (not with
  // the user's -pc_type); -matptap_via or -mat_product_algorithm override it (-matptap_via scalable: PETSc's
  // default: faster products, the higher peak).
  // On one rank hypre's product of the sequential matrices came out wrong (the first Krylov solve diverged at
  // iteration 1 and every 1-rank run fell back to GAMG), so both are used on 2+ ranks only (sequential matrices
  // have neither).
  if (model.size > 1 && !user_pc && !ctx.shell) {  // the shell's coarse operators are summed from its blocks
    PetscBool user_ptap = PETSC_FALSE, user_product = PETSC_FALSE;
    PetscCall(PetscOptionsHasName(nullptr, nullptr, "-matptap_via", &user_ptap));
    PetscCall(PetscOptionsHasName(nullptr, nullptr, "-mat_product_algorithm", &user_product));
    set_ptap = !user_ptap && !user_product;
    if (set_ptap) PetscCall(PetscOptionsSetValue(nullptr, "-matptap_via", lattice_mg ? "hypre" : kGamgPtap));
  }
  PetscCall(PetscInfo(pc, "lattice multigrid: %d levels\n", (int)mg_levels));
  if (!lattice_mg) PetscCall(PCSetType(pc, PCGAMG));
  reference = forces.applied_norm() > 0 ? forces.applied_norm() : 1.0;
  const long max_newton = scene.solver.max_iterations > 0 ? scene.solver.max_iterations : 50;
  tolerance = own_reference ? scene.solver.tolerance : reachable_tolerance(scene, model, forces);
  report.tolerance_used = tolerance;
  PetscCall(SNESSetTolerances(snes, tolerance * reference, 0.0, 0.0, max_newton, 1000000));
  // A tight linear tolerance: an inexact last Newton step leaves errors in soft modes that the force residual
  // hardly sees (1e-6 gave 2e-7 relative differences in elongation between rank counts). With multigrid each
  // decade costs about one Krylov iteration, so this is cheap; -ksp_rtol and -snes_ksp_ew trade it away.
  // The first Newton step of a load step is the exception: its linear solve to 1e-10 is wasted on a nonlinear
  // error of order 1e-4 that the next step removes anyway, so it stops at kFirstRtol (1e-4; the next
  // step's tight solve sets the answer's precision). Peer problem at 64,000 molecules: 3 + 9 Krylov iterations
  // instead of 8 + 9, still 2 Newton steps, the final residual 1.7e-10 instead of 1.0e-10 relative. The larger
  // residual after the first step grows the second step's result by about that factor too, so for tolerances
  // below 1e-9 a third Newton step would be needed (at 1e-3 one already was at 1e-8): the forcing is used only
  // for tolerances of 1e-9 and looser. And only with the lattice multigrid (about a decade per iteration): GAMG
  // on a tiny lattice can gain 8 decades in one iteration, so the loose step itself met the tolerance and ended
  // Newton with an answer only as exact as the tolerance (a calibration test at strain 1e-7 then missed E by
  // 1.0e-6 on 2 ranks). -static_first_rtol R sets it (0: off), -ksp_rtol or -snes_ksp_ew end it.
  // The later steps' solves also end once the residual they leave is far below what Newton tests
  // (converged_or_enough: 0.1 of the Newton tolerance; -static_enough_fraction F, 0: off), with the same Newton
  // count; or below kEnoughShare of the room the step's predicted nonlinear remainder leaves, when that is more
  // (before_newton_step; -static_enough_share S, 0: off).
  PetscCall(KSPSetTolerances(ksp, ctx.rtol, PETSC_DEFAULT, PETSC_DEFAULT, 10000));
  {
    PetscBool user_rtol = PETSC_FALSE, user_ew = PETSC_FALSE;
    PetscCall(PetscOptionsHasName(nullptr, nullptr, "-ksp_rtol", &user_rtol));
    PetscCall(PetscOptionsHasName(nullptr, nullptr, "-snes_ksp_ew", &user_ew));
    PetscReal first = kFirstRtol;
    PetscCall(PetscOptionsGetReal(nullptr, nullptr, "-static_first_rtol", &first, nullptr));
    if (!user_rtol && !user_ew && lattice_mg && tolerance >= 1e-9) ctx.first_rtol = first;
    PetscCall(PetscOptionsGetReal(nullptr, nullptr, "-static_enough_fraction", &ctx.enough_fraction, nullptr));
    PetscCall(PetscOptionsGetReal(nullptr, nullptr, "-static_enough_share", &ctx.enough_share, nullptr));
    if (user_rtol || user_ew) ctx.enough_fraction = 0.0;
    if (ctx.enough_fraction > 0) {
      auto* test = new KrylovTest{&ctx};
      PetscCall(KSPConvergedDefaultCreate(&test->default_test));
      PetscCall(KSPSetConvergenceTest(ksp, converged_or_enough, test, destroy_krylov_test));
    }
  }
  bool gamg_reuse = false;
  if (!lattice_mg && !user_pc && !user_lag && !ctx.shell && model.size > 1) {
    bool explicit_topology = false;
    for (const BodySpec& b : scene.bodies) explicit_topology = explicit_topology || b.unstructured();
    PetscInt from = kGamgReuseMolecules;
    PetscCall(PetscOptionsGetInt(nullptr, nullptr, "-static_gamg_reuse_molecules", &from, nullptr));
    gamg_reuse = explicit_topology && model.global_molecules >= from;
  }
  if (lattice_mg || gamg_reuse) {
    PetscCall(SNESSetLagPreconditioner(snes, -2));
    PetscCall(SNESSetLagPreconditionerPersists(snes, PETSC_TRUE));
  }
  {
    PetscBool reuse = PETSC_TRUE;
    PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-static_reuse_residual", &reuse, nullptr));
    ctx.reuse = reuse == PETSC_TRUE;
  }
  if (forces.energy_line_search()) {  // cell energies (TermStyle::energy_line_search); -snes_linesearch_type wins
    SNESLineSearch line_search;
    PetscCall(SNESGetLineSearch(snes, &line_search));
    PetscCall(SNESLineSearchSetType(line_search, SNESLINESEARCHCP));
    // Its default stop when the step's energy slope is below 1e-15 |step| left the last step of a strain-1e-7
    // test untaken (and SNES still said converged); the slope is what the step is for, however small.
    // And the full step is kept once the energy slope there is below kFullStepSlope of the slope at its start:
    // the secant's lambda is then within about that fraction of 1, and the residual at lambda = 1, already
    // evaluated, is the step's (the default 1e-8 took lambda = 0.999995 at strain 1e-4 and one more residual).
    PetscCall(SNESLineSearchSetTolerances(line_search, PETSC_DEFAULT, PETSC_DEFAULT, kFullStepSlope, 0.0,
                                          PETSC_DEFAULT, PETSC_DEFAULT));
  }
  if (gamg_reuse) PetscCall(PCGAMGSetNSmooths(pc, kGamgSmooths));  // before SNESSetFromOptions: the user's wins
  {
    // The user's -snes_*, -ksp_*, -pc_* options win. One that PETSc refuses here (an unknown type, a malformed
    // number) is bad input: one line and exit 2, the same on every rank (every rank reads the same options), not
    // PETSc's traceback and a failed solve.
    if (const PetscErrorCode refused = SNESSetFromOptions(snes)) {
      const std::string why = last_petsc_error();  // (src/solvers/petsc_errors.hpp)
      throw InputError("PETSc options", user_options(),
                       "refused by PETSc: " + (why.empty() ? "error " + std::to_string(refused) : why));
    }
  }
  {
    PetscBool gamg = PETSC_FALSE;
    PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(pc), PCGAMG, &gamg));
    if (gamg) PetscCall(attach_rigid_modes(model, X, J));
  }
  {
    reuse.active = (lattice_mg || gamg_reuse) && !user_lag;
    if (reuse.active) PetscCall(SNESMonitorSet(snes, watch_reuse, &reuse, nullptr));
  }
  PetscFunctionReturn(0);
}

// solver.operator = "matrix-free": J becomes the shell of MatrixFreeTangent and the lattice multigrid's coarse
// operators come from the force model's block stream, so no fine matrix is stored (docs/benchmarks.md). Only with
// the lattice multigrid and our preconditioner reuse, and when every tangent block stays within the lattice
// stencil (not molecule-molecule contact); otherwise the assembled tangent, with a one-line note.
PetscErrorCode NewtonEquilibrium::Impl::use_matrix_free(bool user_pc, bool user_lag, bool user_galerkin,
                                                        LatticeLevels& hierarchy) {
  PetscFunctionBeginUser;
  std::string why;
  if (user_pc)
    why = "a preconditioner is named (-pc_type) and needs the matrix";
  else if (user_galerkin)
    why = "-pc_mg_galerkin asks PCMG to form the coarse operators from the matrix";
  else if (!lattice_mg)
    why = "there is no lattice multigrid (a mesh or random cloud, or a lattice too small to coarsen)";
  else if (user_lag)
    why = "-snes_lag_preconditioner is given";
  if (why.empty()) {
    galerkin = std::make_unique<LatticeGalerkin>(model, forces.held(), std::move(hierarchy));
    bool stencil = false;
    PetscCall(galerkin->applies(forces, state.x.array(), &stencil));
    if (!stencil) why = "a term couples molecules beyond the lattice stencil (contact)";
  }
  if (why.empty()) {
    // The products' input lives in state.f: every residual evaluation writes the forces whole before reading
    // them, and SNES ends on one (docs/benchmarks.md).
    shell = std::make_unique<MatrixFreeTangent>(model, forces, state.f.data());
    PetscCall(shell->create(&J));
    ctx.shell = shell.get();
    ctx.galerkin = galerkin.get();
    PetscCall(RestTangent::make(model, forces, state.f.data(), static_cast<bool>(ctx.hooks->refresh), &rest));
    ctx.rest = rest.get();
    PetscCall(PCMGSetGalerkin(pc, PC_MG_GALERKIN_NONE));
    PetscCall(PetscInfo(pc, "matrix-free tangent\n"));
    // The user's smoother options keep PETSc's way on every level.
    PetscBool user_smoother = PETSC_FALSE;
    for (const char* name : {"-mg_levels_ksp_type", "-mg_levels_pc_type", "-mg_levels_ksp_chebyshev_eigenvalues",
                             "-mg_levels_ksp_chebyshev_esteig", "-mg_levels_esteig_ksp_type",
                             "-mg_levels_ksp_chebyshev_kind", "-mg_levels_pc_jacobi_type", "-mg_levels_pc_jacobi_abs",
                             "-mg_levels_esteig_ksp_max_it", "-mg_levels_ksp_chebyshev_esteig_noisy"}) {
      PetscBool has = PETSC_FALSE;
      PetscCall(PetscOptionsHasName(nullptr, nullptr, name, &has));
      user_smoother = user_smoother || has ? PETSC_TRUE : PETSC_FALSE;
    }
    ctx.gershgorin = !user_smoother;
    lend_to = snes;
    PetscCall(KSPSetPostSolve(ksp, lend_smoother_vectors, &lend_to));
    // Level 1 as a shell over its stencil rows (no CSR copy: docs/benchmarks.md), unless the user's smoother
    // options may need its entries (SOR, ILU, ...).
    if (!user_smoother) galerkin->keep_level_one_as_stencil();
    PetscCall(PetscOptionsGetReal(nullptr, nullptr, "-static_chebyshev_fraction", &ctx.chebyshev_fraction, nullptr));
    PetscCall(PetscOptionsGetReal(nullptr, nullptr, "-static_symbol_upper", &ctx.symbol_upper, nullptr));
    PetscBool fused = PETSC_TRUE;
    PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-static_fused_chebyshev", &fused, nullptr));
    ctx.fused = fused == PETSC_TRUE;
  } else {
    if (lattice_mg) {  // PCMG's Galerkin products (or the assembled LatticeGalerkin's check) need an AIJ interpolation
      PetscInt levels = 1;
      PetscCall(PCSetType(pc, PCNONE));
      PetscCall(setup_lattice_mg(model, forces.held(), pc, 1000, &levels, nullptr, false));
    }
    if (!by_default) {
      report.note += "solver.operator = matrix-free not used: " + why + ". ";
      PetscCall(PetscPrintf(model.comm, "%s: solver.operator = \"matrix-free\" does not apply (%s): using the "
                                        "assembled tangent\n", kind.c_str(), why.c_str()));
    }
    PetscCall(forces.create_tangent(&J));
  }
  PetscCall(SNESSetJacobian(snes, J, J, tangent, &ctx));
  PetscFunctionReturn(0);
}

PetscErrorCode NewtonEquilibrium::Impl::solve(long steps) {
  PetscFunctionBeginUser;
  double done = 0.0, increment = 1.0 / steps;
  int cutbacks = 0;
  bool retried = false;
  // The state an increment that fails goes back to. A solve that starts from the rest positions (a static
  // solve's first load step) goes back to model.rest and keeps no copy until an increment has converged: 24 B a
  // molecule less at the solve's peak when the load is applied in one step. Agreed by every rank: the copy's
  // VecDuplicate is collective (a rank whose molecules all sit at rest while another's moved hung the job).
  bool from_rest = false;
  state.forces_final = false;
  drop_velocities();
  {
    const PetscScalar* xs;
    PetscCall(VecGetArrayRead(X, &xs));
    int here = std::equal(xs, xs + 3 * model.owned, model.rest.begin()), everywhere = 0;
    PetscCall(VecRestoreArrayRead(X, &xs));
    PetscCallMPI(MPI_Allreduce(&here, &everywhere, 1, MPI_INT, MPI_MIN, model.comm));
    from_rest = everywhere != 0;
  }
  while (done < 1.0 - 1e-12) {
    double target = std::min(1.0, done + increment);
    ctx.load_factor = target;
    if (!from_rest) {
      if (!saved) PetscCall(VecDuplicate(X, &saved));
      PetscCall(VecCopy(X, saved));
    }
    // Agreed (partition/agreement.hpp): a callback's failure on one rank, or SNESSolve's own error return on one
    // rank, is the same one-line error on every rank here, before the fall-backs below decide anything.
    // A solve's forces at given positions are its own (a quasi-static step's history and time): none kept from
    // the last solve's evaluations.
    ctx.last_valid = false;
    const PetscErrorCode solved = SNESSolve(snes, nullptr, X);
    agree(model.comm, [&] {
      if (ctx.error) std::rethrow_exception(std::exchange(ctx.error, nullptr));
      if (solved) throw petsc_failure(kind);  // (thrown by every rank alike, a PETSc error is collective)
    });
    SNESConvergedReason reason;
    PetscInt its, lits;
    PetscCall(SNESGetConvergedReason(snes, &reason));
    PetscCall(SNESGetIterationNumber(snes, &its));
    PetscCall(SNESGetLinearSolveIterations(snes, &lits));
    report.iterations += its;
    report.linear_iterations += lits;
    if (reason > 0) {
      done = target;
      retried = false;
      from_rest = false;
      PetscReal norm;
      PetscCall(SNESGetFunctionNorm(snes, &norm));
      report.residual_history.push_back(norm / reference);
      state.load_factor = done;
      if (record && ctx.hooks->record) {  // history.csv: the load step's equilibrium
        if (done >= 1.0 - 1e-12) {
          // The last one after the solve's memory is released (finish()): its measurement allocates (the
          // velocities given back, the reactions' scratch, 48 B a molecule), and here that was the run's peak.
          record_pending = true;
          continue;
        }
        PetscCall(load_positions(&ctx, X));
        restore_velocities();
        ctx.hooks->record(state);
        drop_velocities();
      }
      continue;
    }
    if (from_rest) {
      PetscScalar* xs;
      PetscCall(VecGetArray(X, &xs));
      std::copy(model.rest.begin(), model.rest.begin() + 3 * model.owned, xs);
      PetscCall(VecRestoreArray(X, &xs));
    } else {
      PetscCall(VecCopy(saved, X));
    }
    KSPConvergedReason kreason;
    PetscCall(KSPGetConvergedReason(ksp, &kreason));
    if (!switched && (kreason == KSP_DIVERGED_INDEFINITE_MAT || kreason == KSP_DIVERGED_INDEFINITE_PC)) {
      // Compressed springs make the geometric stiffness negative: CG cannot go on, GMRES can.
      switched = true;
      PetscCall(KSPSetType(ksp, KSPGMRES));
      PetscCall(KSPSetPCSide(ksp, PC_RIGHT));  // right-preconditioned GMRES minimises the true residual
      report.note += "tangent indefinite at load factor " + std::to_string(target) + ": switched CG to GMRES. ";
      PetscCall(PetscPrintf(model.comm, "%s: the tangent stiffness is indefinite at load factor %g; "
                                        "switching the Krylov method from CG to GMRES\n", kind.c_str(), target));
      continue;
    }
    if (lattice_mg) {
      // GAMG is the more general of the two (it sees the matrix, not the lattice): retry the increment with it,
      // on an assembled tangent.
      lattice_mg = false;
      if (ctx.shell) {
        ctx.shell = nullptr;
        ctx.rest = nullptr;
        Mat assembled;
        PetscCall(forces.create_tangent(&assembled));
        PetscCall(SNESSetJacobian(snes, assembled, assembled, tangent, &ctx));
        PetscCall(MatDestroy(&J));
        J = assembled;
        report.note += "matrix-free tangent replaced by the assembled one for GAMG. ";
      }
      ctx.galerkin = nullptr;
      ctx.first_rtol = 0.0, ctx.enough_fraction = 0.0, ctx.enough = 0.0;  // see the forcing above
      PetscCall(KSPSetTolerances(ksp, ctx.rtol, PETSC_DEFAULT, PETSC_DEFAULT, 10000));
      PetscCall(clear_ptap());
      PetscCall(attach_rigid_modes(model, X, J));
      PetscCall(PCSetType(pc, PCGAMG));
      PetscCall(PCSetFromOptions(pc));
      if (reuse.active) {
        reuse.active = false;  // GAMG is rebuilt every Newton iteration (see Reuse)
        PetscCall(SNESSetLagPreconditioner(snes, 1));
        PetscCall(SNESSetLagPreconditionerPersists(snes, PETSC_FALSE));
      }
      report.note += "lattice multigrid failed at load factor " + std::to_string(target) + ": switched to GAMG. ";
      PetscCall(PetscPrintf(model.comm, "%s: the solve with the lattice multigrid failed at load factor %g "
                                        "(%s); retrying with GAMG\n", kind.c_str(), target, SNESConvergedReasons[reason]));
      continue;
    }
    if (reuse.active && !retried && !reuse.fresh) {
      // A stale preconditioner may be what failed: retry the same increment once with a fresh one first.
      retried = true;
      reuse.rebuilds++;
      PetscCall(rebuild_next(snes, &reuse));
      continue;
    }
    if (++cutbacks > 8) {
      // The last converged load step is the last good state (main() writes it as last_good.h5); the molecule
      // named is the one with the largest unbalanced force there under the load Newton could not reach.
      PetscCall(load_positions(&ctx, X));
      restore_velocities();  // the last good state goes out whole
      forces.forces(state.x.array(), state.v.data(), state.f.data(), target);
      const std::int64_t worst = largest_force_molecule(model, state.f.data());
      const std::string where = describe_molecule(model, state.x.array(), worst);
      throw SolverFailure(kind + ": Newton failed (" + std::string(SNESConvergedReasons[reason]) +
                          ") at load step " + std::to_string(report.residual_history.size() + 1) +
                          " (load factor " + std::to_string(target) + ") after 8 cut-backs: " + where +
                          "; last good state: load factor " + std::to_string(done),
                          SolverFailure::State::last_good);
    }
    increment *= 0.5;
    retried = false;
    report.note += "Newton failed (" + std::string(SNESConvergedReasons[reason]) + ") at load factor " +
                   std::to_string(target) + ": load increment cut to " + std::to_string(increment) + ". ";
    PetscCall(PetscPrintf(model.comm, "%s: Newton failed at load factor %g (%s); cutting the increment to %g\n",
                          kind.c_str(), target, SNESConvergedReasons[reason], increment));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode NewtonEquilibrium::Impl::finish() {
  PetscFunctionBeginUser;
  // The solve is over (finish is the last call): its Krylov, multigrid and line-search vectors, the tangent and
  // the preconditioner's coarse operators go before the final check allocates (the guard's copy of the state, 48 B
  // a molecule); with all of them alive this was the run's peak (docs/benchmarks.md). Results are not touched.
  PetscCall(SNESReset(snes));
  PetscCall(MatDestroy(&J));
  PetscCall(VecDestroy(&saved));
  ctx.galerkin = nullptr;
  galerkin.reset();
  restore_velocities();
  // The final state and its residual, in the common definition.
  ctx.load_factor = 1.0;
  PetscCall(evaluate_forces(&ctx, X));  // the residual is read from state.f (no vector of it is needed)
  if (std::exchange(record_pending, false)) {
    // The last load step's row, at the positions just evaluated: when every rank's evaluation succeeded and the
    // step reached the full loads, its reactions are that evaluation's (the same numbers, no second one).
    int ok = !ctx.error && state.load_factor == 1.0, all = 0;
    MPI_Allreduce(&ok, &all, 1, MPI_INT, MPI_MIN, model.comm);
    state.forces_final = all != 0;
    ctx.hooks->record(state);
  }
  agree(model.comm, [&] {
    if (ctx.error) std::rethrow_exception(std::exchange(ctx.error, nullptr));
  });
  state.forces_final = true;  // for the measurement's reactions (Simulation::measure)
  report.residual = relative_residual(model, forces, state.f.data());
  report.converged = report.residual <= tolerance * 1.0000001;
  check_finite(model, state.x.array(), state.f.data(), report.iterations, kind.c_str());
  {
    StepGuard guard(kind.c_str(), scene, model, forces, state, 128, /*copy=*/false);  // the state is only read
    guard.full_check_as_made();  // a collapsed (inverted) connection at equilibrium is a failure too
  }
  PetscFunctionReturn(0);
}

NewtonEquilibrium::NewtonEquilibrium(const Scene& scene, const LocalModel& model, const ForceModel& forces,
                                     SolverState& state, const SolverHooks& hooks, SolveReport& report,
                                     const char* kind, bool own_reference)
    : impl_(std::make_unique<Impl>(scene, model, forces, state, hooks, report, kind, own_reference)) {
  if (impl_->setup()) throw petsc_failure(kind);
}

NewtonEquilibrium::~NewtonEquilibrium() = default;

void NewtonEquilibrium::solve(long load_steps) {
  PetscErrorCode failed = 0;
  try {
    failed = impl_->solve(std::max(1L, load_steps));
  } catch (...) {
    impl_->restore_velocities();
    throw;
  }
  if (failed) {
    impl_->restore_velocities();
    throw petsc_failure(impl_->kind);
  }
}

void NewtonEquilibrium::release_velocities() { impl_->release_v = true; }

void NewtonEquilibrium::finish() {
  if (impl_->finish() || impl_->clear_ptap()) throw petsc_failure(impl_->kind);
}

Vec NewtonEquilibrium::solution() const { return impl_->X; }

void NewtonEquilibrium::set_force_reference(double reference) {
  impl_->reference = reference;
  if (SNESSetTolerances(impl_->snes, impl_->tolerance * reference, 0.0, 0.0, PETSC_DEFAULT, PETSC_DEFAULT))
    throw petsc_failure(impl_->kind);
}

double NewtonEquilibrium::tolerance() const { return impl_->tolerance; }

void NewtonEquilibrium::record_load_steps() { impl_->record = true; }

void NewtonEquilibrium::target_first_krylov(double fraction) {
  PetscBool user_rtol = PETSC_FALSE, user_ew = PETSC_FALSE;
  if (PetscOptionsHasName(nullptr, nullptr, "-ksp_rtol", &user_rtol) ||
      PetscOptionsHasName(nullptr, nullptr, "-snes_ksp_ew", &user_ew))
    throw petsc_failure(impl_->kind);
  impl_->ctx.targeted = user_rtol || user_ew ? 0.0 : fraction;
}

void NewtonEquilibrium::rebuild_preconditioner() {
  if (impl_->reuse.active && rebuild_next(impl_->snes, &impl_->reuse))
    throw petsc_failure(impl_->kind);
  // GAMG keeps the interpolation of its first set-up (PETSc's -pc_gamg_reuse_interpolation), which a restart
  // cannot know: from here on it aggregates every tangent afresh, in the run that writes checkpoints and in the
  // run restarted from one alike.
  PetscBool gamg = PETSC_FALSE;
  if (PetscObjectTypeCompare(reinterpret_cast<PetscObject>(impl_->pc), PCGAMG, &gamg) ||
      (gamg && PCGAMGSetReuseInterpolation(impl_->pc, PETSC_FALSE)))
    throw petsc_failure(impl_->kind);
}

}  // namespace tissue
