// Static: implicit equilibrium by Newton (newton_equilibrium.hpp), the loads applied in solver.load_steps
// increments.
#include "src/solvers/newton_equilibrium.hpp"

namespace tissue {

SolveReport solve_static(const Scene& scene, const LocalModel& model, const ForceModel& forces, SolverState& state,
                         const SolverHooks& hooks) {
  SolveReport report;
  NewtonEquilibrium newton(scene, model, forces, state, hooks, report, "static");
  newton.record_load_steps();
  newton.release_velocities();
  newton.solve(scene.solver.load_steps);
  newton.finish();
  return report;
}

TISSUE_SOLVER(static, {"static", solve_static, "Newton-Krylov to static equilibrium, load steps, lattice multigrid or GAMG",
                       /*equilibrium=*/true, /*newton=*/true});

}  // namespace tissue
