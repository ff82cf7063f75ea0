// The Newton equilibrium solve (newton_equilibrium.cpp) as an object: set up once (SNES, tangent, the lattice
// multigrid or GAMG), then solved as often as the solver needs (the static solver's load steps, the quasi-static
// solver's time steps), the preconditioner reused across solves.
#pragma once
#include <petscvec.h>

#include <memory>

#include "src/solvers/solver.hpp"

namespace tissue {

class NewtonEquilibrium {
public:
  // Collective. Starts from the state's positions; `kind` names the solver in messages. own_reference: the caller
  // sets the force reference of every solve (set_force_reference) and checks solver.tolerance's round-off floor
  // against it (the quasi-static solver: the reactions of a scene driven by displacements); otherwise the
  // tolerance is checked here against the applied forces (reachable_tolerance).
  NewtonEquilibrium(const Scene& scene, const LocalModel& model, const ForceModel& forces, SolverState& state,
                    const SolverHooks& hooks, SolveReport& report, const char* kind, bool own_reference = false);
  ~NewtonEquilibrium();
  // Collective. Equilibrium from the positions in solution(), the loads raised from 0 to their full value in
  // load_steps increments (cut in half on failure); throws SolverFailure (last good state) when that fails.
  void solve(long load_steps);
  // Collective. The final residual (relative to the applied forces) and the guards' last check into the report.
  void finish();
  // The positions (owned, a PETSc Vec) the next solve starts from and leaves its answer in.
  Vec solution() const;
  // Newton stops when the force residual is below tolerance() times this (N); set up with the applied forces.
  void set_force_reference(double reference);
  double tolerance() const;
  // The next tangent rebuilds the reused preconditioner (GAMG: every tangent from now on). At a checkpoint and
  // at the start of a restart: both runs then build it at the same states, so the continued run and the
  // uninterrupted one solve with the same preconditioners.
  void rebuild_preconditioner();
  // Calls hooks.record after every converged load step, with the state's load_factor set (the static solver).
  void record_load_steps();
  // The static solver: its velocities are zero and read by no term, so they are freed during solve() (24 B a
  // molecule at the solve's peak) and given back, zero, before anything reads them (hooks.record, finish(), an
  // error). Not when they are not all zero or a term reads them.
  void release_velocities();
  // The first Newton step of each solve stops its Krylov solve at `fraction` of the reduction that takes the
  // starting residual to the Newton tolerance (between the tight 1e-10 and 1e-4): a solve that starts close to
  // its answer (the quasi-static solver's extrapolated start) then ends in one Newton step without 10 decades of
  // Krylov work. 0: off; -ksp_rtol or -snes_ksp_ew turn it off.
  void target_first_krylov(double fraction);

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tissue
