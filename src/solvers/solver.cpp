#include "src/solvers/solver.hpp"

#include "src/model/registry.hpp"
#include "src/solvers/molecule_report.hpp"
#include "src/solvers/setup_checks.hpp"

#include <cmath>
#include <cstdio>
#include <algorithm>
#include <ctime>
#include <vector>
#include <limits>

namespace tissue {

double critical_time_step(const ForceModel& forces) {
  // Gershgorin on the mass-scaled stiffness: |lambda| <= max_i (sum_j ||K_ij||) / m_i = max_i 2 sum_c k_c / m_i.
  double rate = forces.largest_stiffness_rate();
  // A term with its own bound (the cell term's h / c_p, docs/poisson.md) replaces Gershgorin's, which would count
  // its stiffness many times over.
  const double wave = forces.terms_critical_time_step();
  if (std::isfinite(wave)) return wave;
  return rate > 0 ? 2.0 / std::sqrt(rate) : std::numeric_limits<double>::infinity();
}

double force_round_off(const LocalModel& model, const ForceModel& forces) {
  // Per molecule: the forces at unit strain (k l0 for a spring), summed, plus those from positions resolved only
  // to eps R / 2 at magnitude R (k R / 2 for a spring), in squares: a slender body far from the origin stalls at
  // R / l0 times its springs' floor (a 10 x 1 x 1 beam of 0.25 tetrahedra: 3.6e-7 relative at R = 10, 5.2e-6 at
  // R = 110; docs/benchmarks.md).
  std::vector<double> scale(model.local, 0.0), squares(model.local, 0.0), magnitude(model.local);
  const double* x = model.rest.data();
  // Each molecule's magnitude once (not twice a connection), k and l0 through their columns (no storage test a read).
  for (int i = 0; i < model.local; ++i)
    magnitude[i] = std::max({std::fabs(x[3 * i]), std::fabs(x[3 * i + 1]), std::fabs(x[3 * i + 2])});
  const ConnectionColumn stiffness = model.table.stiffness_column(), rest_length = model.table.rest_length_column();
  model.end_a.for_each_pair(model.end_b, [&](int c, int a, int b) {
    const double k = std::fabs(stiffness[c]), kl = k * rest_length[c];
    const double kr = k * std::max(magnitude[a], magnitude[b]) / 2;
    scale[a] += kl, scale[b] += kl;
    squares[a] += kr * kr, squares[b] += kr * kr;
  });
  forces.add_force_scale(x, scale, squares);  // the terms' own (cells): Newton stalls at nu -> 1/2 without them
  double sum = 0, total = 0;
  for (int i = 0; i < model.owned; ++i) sum += scale[i] * scale[i] + squares[i];
  MPI_Allreduce(&sum, &total, 1, MPI_DOUBLE, MPI_SUM, model.comm);
  return 2.0 * std::numeric_limits<double>::epsilon() * std::sqrt(total);
}

double reachable_tolerance(const Scene& scene, const LocalModel& model, const ForceModel& forces) {
  const double reference = forces.applied_norm() > 0 ? forces.applied_norm() : 1.0;
  return reachable_tolerance(scene.solver.tolerance, force_round_off(model, forces), reference, "applied forces",
                             model.rank, true);
}

double reachable_tolerance(double tolerance, double round_off, double reference, const char* what, int rank,
                           bool warn) {
  const double floor = round_off / reference;
  if (tolerance >= floor) return tolerance;
  // A floor this high means the load is lost in the round-off of the spring forces: any "converged" answer
  // would be noise. Stop and say so rather than report a number.
  if (floor > 1e-3)
    throw SolverFailure(std::string("the ") + what + " are below the round-off of the spring forces (relative "
                        "residual floor " + std::to_string(floor) + "): no equilibrium can be resolved; apply a "
                        "larger load or displacement; last good state: the one the solve started from",
                        SolverFailure::State::last_good);  // (nothing moved: last_good.h5, not a final.h5)
  if (warn && rank == 0)
    std::fprintf(stderr, "tissue: warning: solver.tolerance %.3g is below the round-off floor of the force "
                         "residual (%.3g for these springs and %s); using %.3g\n",
                 tolerance, floor, what, floor);
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

// The registered solver kinds: solver_styles.inc is generated by CMake from the TISSUE_SOLVER lines of
// src/solvers/*.cpp (one TISSUE_SOLVER_ENTRY(id) each, in file-name order).
#define TISSUE_SOLVER_ENTRY(id) const SolverStyle& solver_style_##id();
#include "solver_styles.inc"
#undef TISSUE_SOLVER_ENTRY

const std::vector<SolverStyle>& solver_styles() {
  static const std::vector<SolverStyle> styles = {
#define TISSUE_SOLVER_ENTRY(id) solver_style_##id(),
#include "solver_styles.inc"
#undef TISSUE_SOLVER_ENTRY
  };
  return styles;
}

const SolverStyle* find_solver(const std::string& name) { return find_style(solver_styles(), name); }

std::vector<std::string> solver_names() { return style_names(solver_styles()); }

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
  const SolverStyle* style = find_solver(scene.solver.kind);  // the scene reader has checked the name
  const double start = MPI_Wtime();
  const std::clock_t cpu_start = std::clock();
  SolveReport report = style->solve(scene, model, forces, state, hooks);
  report.kind = style;
  report.seconds = MPI_Wtime() - start;
  report.cpu_seconds = static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  return report;
}

}  // namespace tissue
