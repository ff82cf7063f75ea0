#include "src/solvers/fused_chebyshev.hpp"

#include <petsc/private/kspimpl.h>  // a KSP type's operations and data
#include <petsc/private/vecimpl.h>  // a vector's duplicate operation

#include <algorithm>
#include <vector>

#include "src/vector_clones.hpp"

namespace tissue {

namespace {

// The estimate's work vectors on idle arrays (fused_chebyshev_idle): the template the estimate's KSPs duplicate
// hands out, in order, vectors of the type PETSc would make (MatCreateVecs' standard type) placed on the arrays;
// once they are used up, vectors made as PETSc makes them. Set only during an estimate (one at a time).
struct IdlePool {
  MPI_Comm comm;
  PetscInt n, N, bs;
  bool seq;
  std::vector<PetscScalar*> arrays;
  std::size_t next = 0;
};
IdlePool* pool = nullptr;

PetscErrorCode pooled_duplicate(Vec, Vec* out);

PetscErrorCode pooled_vector(PetscScalar* array, Vec* out) {
  PetscFunctionBeginUser;
  if (pool->seq)
    PetscCall(VecCreateSeqWithArray(pool->comm, pool->bs, pool->n, array, out));
  else
    PetscCall(VecCreateMPIWithArray(pool->comm, pool->bs, pool->n, pool->N, array, out));
  PetscCall(VecSetOperation(*out, VECOP_DUPLICATE, reinterpret_cast<void (*)(void)>(pooled_duplicate)));
  PetscFunctionReturn(0);
}

PetscErrorCode pooled_duplicate(Vec v, Vec* out) {
  PetscFunctionBeginUser;
  if (pool && pool->next < pool->arrays.size()) {
    PetscCall(pooled_vector(pool->arrays[pool->next++], out));
  } else {  // as VecDuplicate_Seq/_MPI make it (zeroed)
    PetscCall(VecCreate(PetscObjectComm(reinterpret_cast<PetscObject>(v)), out));
    PetscCall(VecSetSizes(*out, v->map->n, v->map->N));
    PetscCall(VecSetBlockSize(*out, v->map->bs));
    PetscCall(VecSetType(*out, reinterpret_cast<PetscObject>(v)->type_name));
  }
  PetscFunctionReturn(0);
}

struct Data {
  PetscReal emax, emin;  // the interval, as KSPChebyshevSetEigenvalues sets it (0: not set)
  Vec inverse_diagonal;  // D^-1 as PCJACOBI keeps it (a zero diagonal entry gives 1)
  PetscObjectState state;  // the operator's state and id it was taken at (PCSetUp's test for a changed operator)
  PetscObjectId id;
  // fused_chebyshev_estimate: the transform and the estimator's iterations, and the operators' ids and states the
  // interval was estimated at (KSPSetUp_Chebyshev's test).
  bool estimate;
  PetscReal tform[4];
  PetscInt steps;
  PetscObjectId est_ids[2];
  PetscObjectState est_states[2];
  IdleVectors idle;  // fused_chebyshev_idle
  void* idle_ctx;
};

constexpr PetscInt kMaxIdle = 8;

// The pool for an estimate on P (its vectors' standard type, size and block size) from the idle vectors of that local
// size, their arrays got (given back by release_pool); agreed on every rank of P, so that the estimate's KSPs make
// their vectors alike. Empty when P's vectors are not of the standard type.
PetscErrorCode make_pool(Data* d, Mat P, IdlePool* out, Vec* sources, PetscInt* nsources) {
  PetscFunctionBeginUser;
  *nsources = 0;
  MPI_Comm comm = PetscObjectComm(reinterpret_cast<PetscObject>(P));
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  VecType type;
  PetscCall(MatGetVecType(P, &type));
  PetscBool standard = PETSC_FALSE, same = PETSC_FALSE;
  PetscCall(PetscStrcmp(type, VECSTANDARD, &standard));
  PetscCall(PetscStrcmp(type, size == 1 ? VECSEQ : VECMPI, &same));
  standard = standard || same ? PETSC_TRUE : PETSC_FALSE;
  PetscInt rows, cols, bs;
  PetscCall(MatGetLocalSize(P, &rows, &cols));
  PetscCall(MatGetSize(P, nullptr, &out->N));
  PetscCall(MatGetBlockSizes(P, nullptr, &bs));
  out->comm = comm, out->n = cols, out->bs = bs, out->seq = size == 1;
  Vec found[kMaxIdle];
  PetscInt count = 0;
  if (d->idle && standard) PetscCall(d->idle(d->idle_ctx, kMaxIdle, &count, found));
  std::vector<PetscScalar*> arrays;
  for (PetscInt i = 0; i < count; ++i) {
    PetscInt n;
    PetscCall(VecGetLocalSize(found[i], &n));
    if (n != cols) continue;
    PetscScalar* a;
    PetscCall(VecGetArray(found[i], &a));
    if (std::find(arrays.begin(), arrays.end(), a) != arrays.end()) {
      PetscCall(VecRestoreArray(found[i], &a));
      continue;
    }
    arrays.push_back(a);
    sources[(*nsources)++] = found[i];
  }
  int mine = static_cast<int>(arrays.size()), all = 0;
  PetscCallMPI(MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, comm));
  arrays.resize(static_cast<std::size_t>(all));
  out->arrays = std::move(arrays);
  if (d->idle) PetscCall(PetscInfo(nullptr, "fused Chebyshev: the estimate's work vectors on %d idle arrays\n", all));
  PetscFunctionReturn(0);
}

PetscErrorCode release_pool(Vec* sources, PetscInt nsources) {
  PetscFunctionBeginUser;
  for (PetscInt i = 0; i < nsources; ++i) {
    PetscScalar* a = nullptr;
    PetscCall(VecRestoreArray(sources[i], &a));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode set_eigenvalues(KSP ksp, PetscReal emax, PetscReal emin) {
  PetscFunctionBeginUser;
  auto* d = static_cast<Data*>(ksp->data);
  PetscCheck(emax > emin, PetscObjectComm(reinterpret_cast<PetscObject>(ksp)), PETSC_ERR_ARG_INCOMP,
             "Chebyshev: the largest eigenvalue %g must exceed the smallest %g", (double)emax, (double)emin);
  PetscCheck(emax * emin > 0, PetscObjectComm(reinterpret_cast<PetscObject>(ksp)), PETSC_ERR_ARG_INCOMP,
             "Chebyshev: both eigenvalues must have one sign (%g, %g)", (double)emax, (double)emin);
  d->emax = emax, d->emin = emin;
  d->estimate = false;
  PetscFunctionReturn(0);
}

PetscErrorCode update_inverse_diagonal(Data* d, Mat P);

// PCJACOBI's application with this smoother's D^-1 (the same products: VecPointwiseMult).
PetscErrorCode apply_inverse_diagonal(PC pc, Vec x, Vec y) {
  PetscFunctionBeginUser;
  Vec* inverse_diagonal;
  PetscCall(PCShellGetContext(pc, &inverse_diagonal));
  PetscCall(VecPointwiseMult(y, x, *inverse_diagonal));
  PetscFunctionReturn(0);
}

// The interval as KSPCHEBYSHEV's set-up estimates it, when the operators changed since the last estimate: a
// KSPCHEBYSHEV made for it on the same operators with the same estimator (its KSPSetUp runs PETSc's estimate) on
// Jacobi (this smoother's D^-1, PCJACOBI's numbers, computed once for the estimate and the smoothing), its CG's
// extreme eigenvalues read as KSPCHEBYSHEV reads them (KSPComputeEigenvalues over its iterations, the least and
// largest real parts) and transformed as it transforms them.
PetscErrorCode estimate(KSP ksp) {
  PetscFunctionBeginUser;
  auto* d = static_cast<Data*>(ksp->data);
  if (!d->estimate) PetscFunctionReturn(0);
  Mat A, P;
  PetscCall(PCGetOperators(ksp->pc, &A, &P));
  PetscObjectId ids[2];
  PetscObjectState states[2];
  PetscCall(PetscObjectGetId(reinterpret_cast<PetscObject>(A), &ids[0]));
  PetscCall(PetscObjectGetId(reinterpret_cast<PetscObject>(P), &ids[1]));
  PetscCall(PetscObjectStateGet(reinterpret_cast<PetscObject>(A), &states[0]));
  PetscCall(PetscObjectStateGet(reinterpret_cast<PetscObject>(P), &states[1]));
  if (d->emax > 0 && ids[0] == d->est_ids[0] && ids[1] == d->est_ids[1] && states[0] == d->est_states[0] &&
      states[1] == d->est_states[1])
    PetscFunctionReturn(0);
  PetscCall(update_inverse_diagonal(d, P));
  KSP reference, estimator;
  PetscCall(KSPCreate(PetscObjectComm(reinterpret_cast<PetscObject>(ksp)), &reference));
  PetscCall(KSPSetType(reference, KSPCHEBYSHEV));
  PetscCall(KSPSetOperators(reference, A, P));
  PC jacobi;
  PetscCall(KSPGetPC(reference, &jacobi));
  PetscCall(PCSetType(jacobi, PCSHELL));
  PetscCall(PCShellSetContext(jacobi, &d->inverse_diagonal));
  PetscCall(PCShellSetApply(jacobi, apply_inverse_diagonal));
  PetscCall(KSPChebyshevEstEigSet(reference, d->tform[0], d->tform[1], d->tform[2], d->tform[3]));
  PetscCall(KSPChebyshevEstEigGetKSP(reference, &estimator));
  PetscCheck(estimator, PetscObjectComm(reinterpret_cast<PetscObject>(ksp)), PETSC_ERR_PLIB,
             "fused Chebyshev: PETSc made no eigenvalue estimator");
  PetscCall(KSPSetType(estimator, KSPCG));
  PetscCall(KSPSetTolerances(estimator, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT, d->steps));
  // The estimate's work vectors: the reference's are duplicates of its solution vector when it has one, the
  // estimator's of its solution (the reference's first): both from the pool's template.
  IdlePool idle;
  Vec sources[kMaxIdle];
  PetscInt nsources = 0;
  PetscCall(make_pool(d, P, &idle, sources, &nsources));
  if (!idle.arrays.empty()) {
    pool = &idle;
    PetscCall(pooled_vector(idle.arrays[0], &reference->vec_sol));  // a template only: never read or written
  }
  const PetscErrorCode estimated = KSPSetUp(reference);  // the estimate
  pool = nullptr;
  if (estimated) {
    PetscCall(KSPDestroy(&reference));
    PetscCall(release_pool(sources, nsources));
    PetscCall(estimated);
  }
  PetscInt n, found;
  PetscCall(KSPGetIterationNumber(estimator, &n));
  PetscReal *re, *im;
  PetscCall(PetscMalloc2(n, &re, n, &im));
  PetscCall(KSPComputeEigenvalues(estimator, n, re, im, &found));
  PetscReal min = PETSC_MAX_REAL, max = PETSC_MIN_REAL;
  for (PetscInt i = 0; i < found; ++i) min = PetscMin(min, re[i]), max = PetscMax(max, re[i]);
  PetscCall(PetscFree2(re, im));
  PetscCall(KSPDestroy(&reference));  // the pooled vectors with it, before their arrays are given back
  PetscCall(release_pool(sources, nsources));
  d->emin = d->tform[0] * min + d->tform[1] * max;
  d->emax = d->tform[2] * min + d->tform[3] * max;
  for (int q = 0; q < 2; ++q) d->est_ids[q] = ids[q], d->est_states[q] = states[q];
  PetscFunctionReturn(0);
}

// D^-1 of the preconditioning operator, recomputed when it changed (as PCSetUp_Jacobi: reciprocal, zeros to 1).
PetscErrorCode update_inverse_diagonal(Data* d, Mat P) {
  PetscFunctionBeginUser;
  PetscObjectState state;
  PetscObjectId id;
  PetscCall(PetscObjectStateGet(reinterpret_cast<PetscObject>(P), &state));
  PetscCall(PetscObjectGetId(reinterpret_cast<PetscObject>(P), &id));
  if (d->inverse_diagonal && state == d->state && id == d->id) PetscFunctionReturn(0);
  if (!d->inverse_diagonal) PetscCall(MatCreateVecs(P, &d->inverse_diagonal, nullptr));
  PetscCall(MatGetDiagonal(P, d->inverse_diagonal));
  PetscScalar* v;
  PetscInt n;
  PetscCall(VecGetLocalSize(d->inverse_diagonal, &n));
  PetscCall(VecGetArray(d->inverse_diagonal, &v));
  for (PetscInt i = 0; i < n; ++i) v[i] = v[i] != 0.0 ? 1.0 / v[i] : 1.0;
  PetscCall(VecRestoreArray(d->inverse_diagonal, &v));
  d->state = state, d->id = id;
  PetscFunctionReturn(0);
}

// The passes below, compiled for AVX-512, AVX2 and the baseline (picked at run time, as the spring kernel's): each
// element's expression is the same in every clone (no fused multiply-adds in this build), so every clone rounds
// alike; the baseline's 2 doubles an instruction were ~2 % of a nu = 0.45 solve's instructions (40^3).
// (TISSUE_CLONES: src/vector_clones.hpp)

// The first step, x_1 = x_0 + s D^-1 (b - A x_0), PETSc's VecAYPX(r, -1, b), VecPointwiseMult and VecAYPX(p, s, x_0)
// in one pass (from a zero guess r = b and x_0 = +0, which PETSc's KSPSolve set).
TISSUE_CLONES void first_step(PetscInt n, PetscScalar s, const PetscScalar* x0, const PetscScalar* b, const PetscScalar* Ax,
                const PetscScalar* dinv, PetscScalar* out) {
  if (x0) {
    for (PetscInt i = 0; i < n; ++i) out[i] = x0[i] + s * ((b[i] - Ax[i]) * dinv[i]);
  } else {
    for (PetscInt i = 0; i < n; ++i) out[i] = 0.0 + s * (b[i] * dinv[i]);
  }
}

// A later step, PETSc's VecAYPX(r, -1, b), VecPointwiseMult and VecAXPBYPCZ(z, a, w, g, p_km1, p_k) in one pass:
// out = a p_km1 + w p_k + g D^-1 (b - A p_k); p_km1 null: the zero guess (+0). out may be p_km1 or p_k.
TISSUE_CLONES void later_step(PetscInt n, PetscScalar a, PetscScalar w, PetscScalar g, const PetscScalar* pkm1, const PetscScalar* pk,
                const PetscScalar* b, const PetscScalar* Apk, const PetscScalar* dinv, PetscScalar* out) {
  if (pkm1) {
    for (PetscInt i = 0; i < n; ++i) out[i] = a * pkm1[i] + w * pk[i] + g * ((b[i] - Apk[i]) * dinv[i]);
  } else {
    for (PetscInt i = 0; i < n; ++i) out[i] = a * 0.0 + w * pk[i] + g * ((b[i] - Apk[i]) * dinv[i]);
  }
}

// KSPSolve_Chebyshev (PETSc 3.18, first kind, no norms) with each step's vector operations in one pass. The
// iterates rotate through p[0] = x, p[1], p[2] as PETSc's do; the last step writes x itself (PETSc copies it there).
PetscErrorCode solve(KSP ksp) {
  PetscFunctionBeginUser;
  auto* d = static_cast<Data*>(ksp->data);
  PetscCheck(d->emax > 0, PetscObjectComm(reinterpret_cast<PetscObject>(ksp)), PETSC_ERR_ORDER,
             "fused Chebyshev: no eigenvalue interval set");
  Mat A, P;
  PetscCall(PCGetOperators(ksp->pc, &A, &P));
  PetscCall(update_inverse_diagonal(d, P));
  const PetscInt maxit = ksp->max_it;
  const PetscInt vectors = maxit > 2 ? 3 : 2;
  if (ksp->nwork < vectors) PetscCall(KSPSetWorkVecs(ksp, vectors));
  Vec b = ksp->vec_rhs, x = ksp->vec_sol, product = ksp->work[1];
  Vec p[3] = {x, ksp->work[0], vectors > 2 ? ksp->work[2] : nullptr};
  // The scalars exactly as KSPSolve_Chebyshev computes them.
  const PetscScalar scale = 2.0 / (d->emax + d->emin);
  const PetscScalar alpha = 1.0 - scale * d->emin;
  const PetscScalar Gamma = 1.0;
  const PetscScalar mu = 1.0 / alpha;
  const PetscScalar omegaprod = 2.0 / alpha;
  PetscScalar c[3];
  int km1 = 0, k = 1, kp1 = 2;
  c[km1] = 1.0;
  c[k] = mu;
  PetscInt n;
  PetscCall(VecGetLocalSize(x, &n));
  const PetscScalar *bb, *dinv, *Ap;
  // The arrays of the iterates (x and the work vectors), got and given back around each pass.
  auto pass = [&](auto&& body) -> PetscErrorCode {
    PetscScalar* arrays[3] = {nullptr, nullptr, nullptr};
    for (int v = 0; v < 3; ++v)
      if (p[v]) PetscCall(VecGetArray(p[v], &arrays[v]));
    PetscCall(VecGetArrayRead(b, &bb));
    PetscCall(VecGetArrayRead(product, &Ap));
    PetscCall(VecGetArrayRead(d->inverse_diagonal, &dinv));
    body(arrays);
    PetscCall(VecRestoreArrayRead(d->inverse_diagonal, &dinv));
    PetscCall(VecRestoreArrayRead(product, &Ap));
    PetscCall(VecRestoreArrayRead(b, &bb));
    for (int v = 0; v < 3; ++v)
      if (p[v]) PetscCall(VecRestoreArray(p[v], &arrays[v]));
    return 0;
  };
  ksp->its = 0;
  const bool zero_guess = ksp->guess_zero;
  if (!zero_guess) PetscCall(MatMult(A, x, product));
  const int first = maxit > 1 ? k : 0;  // one step only: straight into x
  PetscCall(pass([&](PetscScalar** a) { first_step(n, scale, zero_guess ? nullptr : a[0], bb, Ap, dinv, a[first]); }));
  PetscCall(PetscLogFlops((zero_guess ? 2.0 : 4.0) * n));
  bool km1_zero = zero_guess;  // p[km1] is x: +0 from a zero guess until the first step rotates it out
  for (PetscInt i = 1; i < maxit; ++i) {
    ksp->its++;
    c[kp1] = 2.0 * mu * c[k] - c[km1];
    const PetscScalar omega = omegaprod * c[k] / c[kp1];
    PetscCall(MatMult(A, p[k], product));
    const int out = i == maxit - 1 ? 0 : kp1;
    PetscCall(pass([&](PetscScalar** a) {
      later_step(n, 1.0 - omega, omega, omega * Gamma * scale, km1_zero ? nullptr : a[km1], a[k], bb, Ap, dinv, a[out]);
    }));
    PetscCall(PetscLogFlops(8.0 * n));
    km1_zero = false;
    const int t = km1;
    km1 = k, k = kp1, kp1 = t;
  }
  ksp->reason = KSP_CONVERGED_ITS;
  PetscFunctionReturn(0);
}

PetscErrorCode setup(KSP ksp) {
  PetscFunctionBeginUser;
  PetscCall(estimate(ksp));  // where KSPCHEBYSHEV's set-up estimates (PCSetUp of the multigrid)
  // Made once: the set-up runs again for every new operator (the estimate), and the line search holds the first
  // two (lend_smoother_vectors: new ones would leave it two of its own).
  const PetscInt vectors = ksp->max_it > 2 ? 3 : 2;
  if (ksp->nwork < vectors) PetscCall(KSPSetWorkVecs(ksp, vectors));
  PetscFunctionReturn(0);
}

PetscErrorCode reset(KSP ksp) {
  PetscFunctionBeginUser;
  PetscCall(VecDestroy(&static_cast<Data*>(ksp->data)->inverse_diagonal));
  PetscFunctionReturn(0);
}

PetscErrorCode destroy(KSP ksp) {
  PetscFunctionBeginUser;
  PetscCall(reset(ksp));
  PetscCall(PetscObjectComposeFunction(reinterpret_cast<PetscObject>(ksp), "KSPChebyshevSetEigenvalues_C", nullptr));
  PetscCall(KSPDestroyDefault(ksp));
  PetscFunctionReturn(0);
}

PetscErrorCode view(KSP ksp, PetscViewer viewer) {
  PetscFunctionBeginUser;
  auto* d = static_cast<Data*>(ksp->data);
  PetscBool ascii;
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(viewer), PETSCVIEWERASCII, &ascii));
  if (ascii)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  Chebyshev on Jacobi, vector operations fused: eigenvalues %g, %g\n",
                                     (double)d->emin, (double)d->emax));
  PetscFunctionReturn(0);
}

PetscErrorCode create(KSP ksp) {
  PetscFunctionBeginUser;
  Data* d;
  PetscCall(PetscNew(&d));
  ksp->data = d;
  PetscCall(KSPSetSupportedNorm(ksp, KSP_NORM_NONE, PC_LEFT, 1));
  PetscCall(KSPSetSupportedNorm(ksp, KSP_NORM_NONE, PC_RIGHT, 1));
  ksp->setupnewmatrix = PETSC_TRUE;  // the set-up runs again for a new operator (the estimate), as KSPCHEBYSHEV's
  ksp->ops->setup = setup;
  ksp->ops->solve = solve;
  ksp->ops->reset = reset;
  ksp->ops->destroy = destroy;
  ksp->ops->view = view;
  ksp->ops->buildsolution = KSPBuildSolutionDefault;
  ksp->ops->buildresidual = KSPBuildResidualDefault;
  PetscCall(PetscObjectComposeFunction(reinterpret_cast<PetscObject>(ksp), "KSPChebyshevSetEigenvalues_C",
                                       set_eigenvalues));
  PetscFunctionReturn(0);
}

}  // namespace

PetscErrorCode fused_chebyshev_estimate(KSP ksp, PetscReal a, PetscReal b, PetscReal c, PetscReal d,
                                        PetscInt steps) {
  PetscFunctionBeginUser;
  PetscBool fused;
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(ksp), kFusedChebyshev, &fused));
  PetscCheck(fused, PetscObjectComm(reinterpret_cast<PetscObject>(ksp)), PETSC_ERR_ARG_WRONG,
             "fused_chebyshev_estimate: not a %s", kFusedChebyshev);
  auto* data = static_cast<Data*>(ksp->data);
  data->estimate = true;
  data->tform[0] = a, data->tform[1] = b, data->tform[2] = c, data->tform[3] = d;
  data->steps = steps;
  data->emax = data->emin = 0;  // none until the first estimate
  data->est_ids[0] = data->est_ids[1] = 0;
  PetscFunctionReturn(0);
}

PetscErrorCode fused_chebyshev_idle(KSP ksp, IdleVectors idle, void* ctx) {
  PetscFunctionBeginUser;
  PetscBool fused;
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(ksp), kFusedChebyshev, &fused));
  PetscCheck(fused, PetscObjectComm(reinterpret_cast<PetscObject>(ksp)), PETSC_ERR_ARG_WRONG,
             "fused_chebyshev_idle: not a %s", kFusedChebyshev);
  auto* data = static_cast<Data*>(ksp->data);
  data->idle = idle, data->idle_ctx = ctx;
  PetscFunctionReturn(0);
}

PetscErrorCode register_fused_chebyshev() {
  PetscFunctionBeginUser;
  static bool registered = false;
  if (!registered) PetscCall(KSPRegister(kFusedChebyshev, create));
  registered = true;
  PetscFunctionReturn(0);
}

}  // namespace tissue
