// Relaxation, the paper's way to equilibrium: explicit damped dynamics until the relative force residual falls
// below solver.tolerance. The damping is FIRE (Bitzek et al., PRL 97, 170201, 2006), the same minimizer as the
// LAMMPS peer: velocities are steered along the force while power is positive and zeroed when it turns negative,
// and the time step grows up to the one the scene gives (default: 0.9 x the critical time step).
#include <algorithm>
#include <cmath>

#include "src/solvers/guards.hpp"
#include "src/solvers/progress.hpp"
#include "src/solvers/setup_checks.hpp"
#include "src/solvers/solver.hpp"

namespace tissue {

SolveReport solve_relaxation(const Scene& scene, const LocalModel& model, const ForceModel& forces,
                             SolverState& state, const SolverHooks& hooks) {
  SolveReport report;
  report.critical_time_step = critical_time_step(forces);
  const double dt_max = scene.solver.time_step ? checked_time_step(scene, model, *scene.solver.time_step,
                                                                    report.critical_time_step, "relaxation")
                                               : 0.9 * report.critical_time_step;
  report.time_step = dt_max;
  const long n_max = std::max({model.shape.n[0], model.shape.n[1], model.shape.n[2]});
  const long max_iterations = scene.solver.max_iterations > 0 ? scene.solver.max_iterations : 100000 + 5000 * n_max;
  const int n = 3 * model.owned;
  const double* m = model.mass.data();
  double* x = state.x.array();
  double* v = state.v.data();
  double* f = state.f.data();
  const auto& held = forces.held();

  // FIRE parameters: the published defaults.
  const int n_delay = 5;
  const double f_inc = 1.1, f_dec = 0.5, alpha_start = 0.1, f_alpha = 0.99;
  // FIRE's adaptive state lives in the SolverState, so that a checkpoint continues it bit for bit.
  if (!state.restarted) state.fire_dt = 0.5 * dt_max, state.fire_alpha = alpha_start, state.fire_positive = 0;
  double& dt = state.fire_dt;
  double& alpha = state.fire_alpha;
  long& positive = state.fire_positive;
  state.time_step = dt_max;

  const double tolerance = reachable_tolerance(scene, model, forces);
  report.tolerance_used = tolerance;
  Progress progress("relaxation", scene.output.progress, model.comm);
  state.x.update_ghosts();
  if (hooks.refresh) hooks.refresh(x);
  forces.forces(x, v, f);
  double residual = relative_residual(model, forces, f);
  // NaN, Inf and divergence caught at the iteration they appear (the residual is reduced anyway); connection
  // lengths every 128 iterations; the last good state is kept (guards.hpp).
  StepGuard guard("relaxation", scene, model, forces, state);
  long it = 0;
  for (;; ++it) {
    guard.relaxation_step(residual);
    if (it % 100 == 0) report.residual_history.push_back(residual);
    progress.update(it, residual, tolerance, 0);
    if (residual <= tolerance) {
      report.converged = true;
      break;
    }
    if (it >= max_iterations) break;
    if (it > 0) {
      if (hooks.snapshot && scene.output.snapshot_every > 0 && state.step % scene.output.snapshot_every == 0)
        hooks.snapshot(state);
      if (step_boundary(scene, model, state, hooks, 1)) {  // a reduction per iteration is already paid here
        report.interrupted = true;
        break;
      }
    }

    // Power P = F . v and the norms, in one reduction.
    double local[3] = {0, 0, 0}, global[3];
    for (int i = 0; i < n; ++i) local[0] += f[i] * v[i], local[1] += f[i] * f[i], local[2] += v[i] * v[i];
    MPI_Allreduce(local, global, 3, MPI_DOUBLE, MPI_SUM, model.comm);
    if (global[0] > 0) {
      const double mix = global[1] > 0 ? alpha * std::sqrt(global[2] / global[1]) : 0.0;
      for (int i = 0; i < n; ++i) v[i] = (1.0 - alpha) * v[i] + mix * f[i];
      if (++positive > n_delay) dt = std::min(dt * f_inc, dt_max), alpha *= f_alpha;
    } else {
      std::fill(v, v + n, 0.0);
      dt *= f_dec, alpha = alpha_start, positive = 0;
    }
    // Semi-implicit Euler, as FIRE prescribes.
    for (int i = 0; i < model.owned; ++i)
      for (int d = 0; d < 3; ++d) {
        const int j = 3 * i + d;
        v[j] = held[j] ? 0.0 : v[j] + dt * f[j] / m[i];
        x[j] += dt * v[j];
      }
    state.x.update_ghosts();
    if (hooks.refresh) hooks.refresh(x);
    forces.forces(x, v, f);
    residual = relative_residual(model, forces, f);
    ++state.step;
  }
  guard.full_check();
  report.iterations = it;
  report.guard_checks = guard.checks();
  report.guard_seconds = guard.seconds();
  report.residual = residual;
  report.residual_history.push_back(residual);
  if (report.converged) std::fill(state.v.begin(), state.v.end(), 0.0);  // equilibrium: at rest
  // history.csv: one row, the equilibrium found (as a static solve's single load step; FIRE's iterations are not
  // a time line). An interrupted run has not reached it.
  if (hooks.record && !report.interrupted) hooks.record(state);
  return report;
}

TISSUE_SOLVER(relaxation, {"relaxation", solve_relaxation, "FIRE damped dynamics to static equilibrium",
                           /*equilibrium=*/true, /*newton=*/false, /*explicit_steps=*/true, /*integrates_time=*/false,
                           /*settles_on_obstacles=*/true});

}  // namespace tissue
