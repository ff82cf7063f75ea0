#include "src/solvers/solver.hpp"

#include "src/solvers/guards.hpp"

#include <cmath>
#include <cstdio>
#include <ctime>
#include <vector>
#include <limits>

namespace tissue {

double critical_time_step(const ForceModel& forces) {
  // Gershgorin on the mass-scaled stiffness: |lambda| <= max_i (sum_j ||K_ij||) / m_i = max_i 2 sum_c k_c / m_i.
  double rate = forces.largest_stiffness_rate();
  return rate > 0 ? 2.0 / std::sqrt(rate) : std::numeric_limits<double>::infinity();
}

double reachable_tolerance(const Scene& scene, const LocalModel& model, const ForceModel& forces) {
  std::vector<double> scale(model.local, 0.0);
  for (int c = 0; c < model.connections(); ++c) {
    const double kl = std::fabs(model.k(c)) * model.l0(c);
    scale[model.end_a[c]] += kl, scale[model.end_b[c]] += kl;
  }
  double sum = 0, total = 0;
  for (int i = 0; i < model.owned; ++i) sum += scale[i] * scale[i];
  MPI_Allreduce(&sum, &total, 1, MPI_DOUBLE, MPI_SUM, model.comm);
  const double reference = forces.applied_norm() > 0 ? forces.applied_norm() : 1.0;
  const double floor = 2.0 * std::numeric_limits<double>::epsilon() * std::sqrt(total) / reference;
  if (scene.solver.tolerance >= floor) return scene.solver.tolerance;
  // A floor this high means the load is lost in the round-off of the spring forces: any "converged" answer
  // would be noise. Stop and say so rather than report a number.
  if (floor > 1e-3)
    throw SolverFailure("the applied forces are below the round-off of the spring forces (relative residual "
                        "floor " + std::to_string(floor) + "): no equilibrium can be resolved; apply a larger load");
  if (model.rank == 0)
    std::fprintf(stderr, "tissue: warning: solver.tolerance %.3g is below the round-off floor of the force "
                         "residual (%.3g for these springs and loads); using %.3g\n",
                 scene.solver.tolerance, floor, floor);
  return floor;
}

double relative_residual(const LocalModel& model, const ForceModel& forces, const double* f) {
  double sum = 0;
  for (int i = 0; i < 3 * model.owned; ++i) sum += f[i] * f[i];  // held components are already zero
  double total = 0;
  MPI_Allreduce(&sum, &total, 1, MPI_DOUBLE, MPI_SUM, model.comm);
  double reference = forces.applied_norm();
  return reference > 0 ? std::sqrt(total) / reference : std::sqrt(total);
}

void check_finite(const LocalModel& model, const double* x, const double* f, long step, const char* what) {
  long long bad = std::numeric_limits<long long>::max();
  for (int i = 0; i < model.owned; ++i)
    for (int d = 0; d < 3; ++d)
      if (!std::isfinite(x[3 * i + d]) || !std::isfinite(f[3 * i + d])) bad = std::min<long long>(bad, model.id[i]);
  long long first = 0;
  MPI_Allreduce(&bad, &first, 1, MPI_LONG_LONG, MPI_MIN, model.comm);
  if (first != std::numeric_limits<long long>::max())
    throw SolverFailure(std::string(what) + " diverged at step " + std::to_string(step) + ": " +
                        describe_molecule(model, x, first) + " has a non-finite position or force",
                        SolverFailure::State::nothing);
}

volatile std::sig_atomic_t stop_requested = 0;

bool step_boundary(const Scene& scene, const LocalModel& model, const SolverState& state, const SolverHooks& hooks,
                   long every) {
  bool stop = false;
  if (every > 0 && state.step % every == 0) {
    int mine = stop_requested ? 1 : 0, any = 0;
    MPI_Allreduce(&mine, &any, 1, MPI_INT, MPI_MAX, model.comm);
    stop = any != 0;
  }
  const long cadence = scene.output.checkpoint_every;
  if (hooks.checkpoint && (stop || (cadence > 0 && state.step > 0 && state.step % cadence == 0)))
    hooks.checkpoint(state);
  return stop;
}

SolveReport solve(const Scene& scene, const LocalModel& model, const ForceModel& forces, SolverState& state,
                  const SolverHooks& hooks) {
  check_connections(scene, model);  // zero rest lengths: bad input, before any step
  const std::string& kind = scene.solver.kind;
  const double start = MPI_Wtime();
  const std::clock_t cpu_start = std::clock();
  SolveReport report = kind == "relaxation" ? solve_relaxation(scene, model, forces, state, hooks)
                       : kind == "dynamic"  ? solve_dynamic(scene, model, forces, state, hooks)
                                            : solve_static(scene, model, forces, state, hooks);
  report.seconds = MPI_Wtime() - start;
  report.cpu_seconds = static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  return report;
}

}  // namespace tissue
