// Quasi-static: equilibrium at every time step, no inertia (solver.kind = "quasi-static"). The loads and holds
// follow their histories ([[load]] / [[fix]] history, [[fix]] displacement) and terms with internal variables (the
// viscoelastic history) advance by each step. Time (../shared/interface.md): the run starts undeformed with zero
// history at t = 0-; the factors at t = 0 are a step solved at t = 0 (dt = 0: the instantaneous response), then
// each step advances by solver.time_step up to solver.steps steps or solver.end_time, shortened to land exactly
// on every history's breakpoints. One Newton solver (newton_equilibrium.hpp) serves every step, so the lattice
// multigrid is built once and reused. Each step's Newton starts from the last two equilibria extrapolated (see
// Extrapolation), so that a steady motion (a ramp, creep) costs few Newton iterations.
#include <fmt/format.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include <petscsys.h>

#include "src/solvers/newton_equilibrium.hpp"
#include "src/solvers/petsc_errors.hpp"
#include "src/solvers/progress.hpp"

namespace tissue {

namespace {

// Every breakpoint time after 0 of the loads' and holds' histories, ascending.
std::vector<double> breakpoints(const Scene& scene) {
  std::vector<double> t;
  for (const auto& l : scene.loads)
    for (const auto& p : l.history) t.push_back(p[0]);
  for (const auto& f : scene.fixes)
    for (const auto& p : f.history) t.push_back(p[0]);
  std::sort(t.begin(), t.end());
  t.erase(std::unique(t.begin(), t.end()), t.end());
  return t;
}

// Whether anything acts at time t: a load or a hold that moves, at a non-zero factor.
bool loaded(const Scene& scene, double t) {
  if (scene.physics.gravity) return true;
  for (const auto& l : scene.loads)
    if (l.force != Vec3{0.0, 0.0, 0.0} && history_factor(l.history, t) != 0.0) return true;
  for (const auto& f : scene.fixes)
    if (f.displacement != Vec3{0.0, 0.0, 0.0} && history_factor(f.history, t) != 0.0) return true;
  return false;
}

double norm(const std::vector<Vec3>& r) {
  double s = 0;
  for (const auto& v : r)
    for (double c : v) s += c * c;
  return std::sqrt(s);
}

// The owned positions of X into the state, ghosts refreshed.
void load_state(Vec X, const LocalModel& model, SolverState& state) {
  const PetscScalar* xs;
  if (VecGetArrayRead(X, &xs)) throw petsc_failure("quasi-static");
  std::memcpy(state.x.array(), xs, sizeof(double) * 3 * model.owned);
  if (VecRestoreArrayRead(X, &xs)) throw petsc_failure("quasi-static");
  state.x.update_ghosts();
}

// The start of a step's Newton solve: x_n + (x_n - x_(n-1)) dt_n / dt_(n-1) on the free components, linear in
// time from the last two equilibria, exact for a linear response to a linear ramp, so that a moving step's Newton
// begins within the motion's curvature of its answer instead of a whole step's motion away (a ramp at 8,000
// molecules: 1 Newton iteration a step instead of 2). The held components keep the positions their [[fix]] gives.
// There is no rate to extrapolate (the step starts from x_n) after t = 0 (its dt = 0 is a jump, not a rate), after
// a step that ended on a history breakpoint (the loads' and holds' rates change there), at a restart (x_(n-1) is
// not in the checkpoint) and after a step that wrote a checkpoint (so the uninterrupted run and the restarted one
// start the next step alike: restarts stay byte for byte). -quasi_static_extrapolate false turns it off. Costs
// one vector of positions (only quasi-static runs).
class Extrapolation {
public:
  Extrapolation(const ForceModel& forces, Vec like) : held_(forces.held()) {
    PetscBool on = PETSC_TRUE;
    if (PetscOptionsGetBool(nullptr, nullptr, "-quasi_static_extrapolate", &on, nullptr) ||
        (on && VecDuplicate(like, &previous_)))
      throw petsc_failure("quasi-static");
  }
  ~Extrapolation() { VecDestroy(&previous_); }
  Extrapolation(const Extrapolation&) = delete;
  Extrapolation& operator=(const Extrapolation&) = delete;
  // X holds x_n (its held components already moved to the step's end, which this leaves alone): keeps x_n for
  // the next step and, when the last step gave a rate, moves the free components to the guess for a step of dt.
  void guess(Vec X, double dt) {
    if (!previous_) return;
    PetscScalar *x, *p;
    PetscInt n;
    if (VecGetLocalSize(X, &n) || VecGetArray(X, &x) || VecGetArray(previous_, &p))
      throw petsc_failure("quasi-static");
    const double ratio = last_dt_ > 0 && dt > 0 ? dt / last_dt_ : 0.0;
    for (PetscInt j = 0; j < n; ++j) {
      if (held_[j]) continue;
      const double now = x[j];
      if (ratio > 0) x[j] = now + (now - p[j]) * ratio;
      p[j] = now;
    }
    if (VecRestoreArray(previous_, &p) || VecRestoreArray(X, &x))
      throw petsc_failure("quasi-static");
    last_dt_ = dt;
  }
  void reset() { last_dt_ = 0.0; }  // the next step starts from x_n

private:
  const std::vector<std::uint8_t>& held_;
  Vec previous_ = nullptr;  // x_(n-1), free components (null: off)
  double last_dt_ = 0.0;    // the last step's dt, 0: no rate to extrapolate
};

}  // namespace

SolveReport solve_quasi_static(const Scene& scene, const LocalModel& model, const ForceModel& forces,
                               SolverState& state, const SolverHooks& hooks) {
  SolveReport report;
  const double dt = *scene.solver.time_step;  // the scene reader requires it
  const double end = scene.solver.end_time ? *scene.solver.end_time : dt * static_cast<double>(scene.solver.steps);
  // The step grows by solver.time_step_growth after every step, up to max_time_step, and starts from dt again
  // after a breakpoint; state.time_step is the next step's (a checkpoint keeps it).
  const double growth = scene.solver.time_step_growth;
  const double largest = scene.solver.max_time_step ? *scene.solver.max_time_step : dt * 1e300;
  double h = state.restarted && state.time_step > 0 ? state.time_step : dt;
  report.time_step = dt;
  state.time_step = h;
  const double slack = 1e-9 * dt;  // a step within this of a breakpoint or the end lands on it
  const std::vector<double> marks = breakpoints(scene);
  const bool history = forces.has_history();

  // The residual's reference is this solver's (below): the round-off floor is checked against it, step by step.
  NewtonEquilibrium newton(scene, model, forces, state, hooks, report, "quasi-static", /*own_reference=*/true);
  Vec X = newton.solution();
  Extrapolation extrapolation(forces, X);
  {
    // A step starting close to its answer needs only the Krylov decades that reach the tolerance (see
    // target_first_krylov): -quasi_static_targeted_krylov 0.01 halves a moving step's Krylov iterations
    // (docs/benchmarks.md). Off by default: its answers are exact to the tolerance only, not to the round-off
    // a tight last solve gives, and rank counts then differ by more than viscoelastic_test's 1e-10 (1.3e-10).
    PetscReal fraction = 0.0;
    if (PetscOptionsGetReal(nullptr, nullptr, "-quasi_static_targeted_krylov", &fraction, nullptr))
      throw petsc_failure("quasi-static");
    newton.target_first_krylov(fraction);
  }
  Progress progress("quasi-static", scene.output.progress, model.comm);
  const long total = static_cast<long>(std::ceil(end / dt - 1e-9));
  std::vector<Vec3> reactions(scene.fixes.size(), Vec3{0, 0, 0});
  bool initial = state.step == 0 && state.time == 0.0 && !state.restarted;
  // A restart: the reactions the last step ended with (the next residual reference), from the checkpoint's state
  // and committed history, the same numbers the uninterrupted run had.
  if (state.restarted && !scene.fixes.empty()) {
    forces.set_time(state.time);
    reactions = forces.reactions(state.x.array(), state.v.data(), state.f.data());
  }
  if (state.restarted) newton.rebuild_preconditioner();  // as the run that wrote the checkpoint did there
  double worst = 0.0;
  // Below this the residual is the springs' round-off (a step with nothing loaded yet): already in equilibrium.
  const double round_off = force_round_off(model, forces);
  const double floor = std::max(round_off / newton.tolerance(), DBL_MIN);
  double tolerance_used = newton.tolerance();
  bool warned = false;
  while (initial || state.time < end - slack) {
    double next = initial ? 0.0 : std::min(state.time + h, end);
    for (double m : marks)
      if (m > state.time + slack && m < next - slack) {
        next = m;
        break;
      }
    if (std::fabs(next - end) <= slack) next = end;
    bool landed = false;  // the step ends on a breakpoint: the next one starts from time_step again
    for (double m : marks) landed = landed || std::fabs(m - next) <= slack;
    forces.set_time(next);
    if (history) forces.begin_step(next - state.time);
    // The holds move to where they are at `next`; the Newton solve starts from the last equilibrium.
    PetscScalar* xs;
    if (VecGetArray(X, &xs)) throw petsc_failure("quasi-static");
    forces.place_held(next, xs);
    if (VecRestoreArray(X, &xs)) throw petsc_failure("quasi-static");
    // The residual's reference: the largest of the unbalanced force the step starts with (the change of loads and
    // holds), the reactions of the last step (what the holds carry) and the loads at full value, so that a scene
    // driven only by displacements, or a hold whose history only creeps, is measured against the forces it carries.
    load_state(X, model, state);
    forces.forces(state.x.array(), state.v.data(), state.f.data());
    const double start = relative_residual(model, forces, state.f.data()) *
                         (forces.applied_norm() > 0 ? forces.applied_norm() : 1.0);
    // The held molecules move alone at first: a step of them by more than about a lattice spacing inverts the
    // cells beside them (non-finite forces), which no Newton solve recovers from. One agreed line (a reduced value).
    if (!std::isfinite(start))
      throw SolverFailure(fmt::format("quasi-static: the step to t = {:g} s moves the holds so far that the forces "
                                      "beside them are not finite (cells or connections inverted): ramp the hold "
                                      "(a [[fix]] history over several steps)", next),
                          SolverFailure::State::nothing);
    const double carried = std::max({start, norm(reactions), forces.applied_norm()});
    // solver.tolerance is reachable when the round-off of the spring forces is below it relative to what the step
    // carries (the reactions of a scene driven by displacements, not 1 N): else the floor is used (one warning)
    // and a step that is loaded but carries no more than 1e3 times the round-off stops the run. A step with
    // nothing loaded (every load and moved hold at factor 0) is in equilibrium at the round-off.
    if (loaded(scene, next)) {
      tolerance_used = std::max(tolerance_used, reachable_tolerance(newton.tolerance(), round_off, carried,
                                                                    "reactions and applied forces", model.rank,
                                                                    !warned));
      warned = tolerance_used > newton.tolerance();
    }
    const double reference = std::max(carried, floor);
    newton.set_force_reference(reference);
    // The reference above is the unbalanced force of the last equilibrium with the holds moved, extrapolated or
    // not, so the tolerance does not depend on the guess.
    extrapolation.guess(X, next - state.time);
    newton.solve(1);
    load_state(X, model, state);
    forces.forces(state.x.array(), state.v.data(), state.f.data());
    check_finite(model, state.x.array(), state.f.data(), state.step, "quasi-static");
    const double residual = relative_residual(model, forces, state.f.data()) *
                            (forces.applied_norm() > 0 ? forces.applied_norm() : 1.0) / reference;
    worst = std::max(worst, residual);
    // The held components' forces of that evaluation: the same sums as reactions() at these positions, without
    // a second evaluation.
    reactions = forces.last_reactions();
    if (history) forces.commit_step(state.x.array());
    state.time = next;
    if (!initial) ++state.step;
    if (!initial) h = landed ? dt : std::min(h * growth, largest);
    state.time_step = h;
    initial = false;
    if (hooks.record) hooks.record(state);
    progress.update(state.step, residual, newton.tolerance(), total);
    if (hooks.snapshot && scene.output.snapshot_every > 0 && state.step > 0 &&
        state.step % scene.output.snapshot_every == 0 && state.time < end - slack)
      hooks.snapshot(state);
    // Checkpoints (and a stop asked by a signal) at the step's end, after its history.csv row; a checkpoint
    // rebuilds the preconditioner at the next tangent, as the restart does.
    const long cadence = scene.output.checkpoint_every;
    if (cadence > 0 && state.step > 0 && state.step % cadence == 0) {
      newton.rebuild_preconditioner();
      extrapolation.reset();  // a restart from here has no x_(n-1)
    }
    if (landed) extrapolation.reset();  // the rates change at a breakpoint
    if (state.time < end - slack && step_boundary(scene, model, state, hooks, 1)) {
      report.interrupted = true;
      break;
    }
  }
  report.residual = worst;
  report.tolerance_used = tolerance_used;
  report.converged = !report.interrupted && worst <= newton.tolerance() * 1.0000001;
  return report;
}

TISSUE_SOLVER(quasi_static, {"quasi-static", solve_quasi_static,
                             "equilibrium at every time step (loads and holds in time, viscoelastic history)",
                             /*equilibrium=*/false, /*newton=*/true, /*explicit_steps=*/false,
                             /*integrates_time=*/false, /*settles_on_obstacles=*/false, /*time_line=*/true,
                             /*moves_holds=*/true, /*needs_time_step=*/true, /*checkpointed=*/true});

}  // namespace tissue
