// Guards: the solvers' cheap per-step checks that a run never fails silently (see docs/stability.md); the checks
// made once at set-up (the time step, the connections) are src/solvers/setup_checks.hpp, the reports naming a
// molecule src/solvers/molecule_report.hpp.
//
//  - during the solve (StepGuard): NaN or Inf caught within kReduceEvery (16) steps (one more where the solver's
//    16th step drifted on: the check is then made at the next, whole, step) and the step where it first
//    appeared named (dynamic: each rank notes the first step its kinetic energy is non-finite, at no cost; the
//    ranks compare notes every 16 steps, the cadence of the signal check; relaxation: every iteration),
//    energy growth (dynamic, within 16 steps) and divergence (relaxation) caught early, a connection shorter than 1e-3 of its rest length (inverted, collapsed) caught
//    at every full check; each is a SolverFailure naming the solver, the step, the molecule and the connection
//    with the largest strain at that molecule;
//  - -tissue_guards false in PETSc's options database (`tissue run s.toml -- -tissue_guards false`, or
//    PETSC_OPTIONS; benchmarks only: run_scripts/bench_guards.sh measures the guards' cost with it) makes dynamic_step and relaxation_step return at once: no reduction, no periodic check, no
//    copy of the last good state. A warning is printed; never use it for results.
//  - the last good state: the guard keeps a copy of the state at every full check that passed; on a failure it
//    puts that state back into the SolverState before throwing, and main() writes it as DIR/last_good.h5.
#pragma once
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "src/solvers/solver.hpp"

namespace tissue {

// A connection shorter than this fraction of its rest length is a failure (collapsed or inverted).
constexpr double kCollapsedLengthRatio = 1e-3;
// Dynamic: steps between the guard's reductions (the global kinetic energy, any rank's non-finite state): one
// reduction per step costs too much of a step (docs/stability.md, docs/benchmarks.md).
constexpr long kReduceEvery = 16;

class StepGuard {
public:
  // `every`: iterations between full checks (finite state, connection lengths, energy) and copies of the
  // last good state.
  // `copy` false: the solver does not change the state while this guard lives (a final check only), so the state
  // itself stays the last good one: no copy (48 B a molecule), and a failure leaves it as it is; no energies
  // either (kinetic_energy() is 0): only full_check_as_made() may follow.
  StepGuard(const char* solver, const Scene& scene, const LocalModel& model, const ForceModel& forces,
            SolverState& state, long every = 128, bool copy = true);

  // Dynamic, after every step: `local_kinetic` is this rank's sum of m v^2 / 2 (computed in the solver's own
  // loop; NaN and Inf propagate into it). No communication but every kReduceEvery steps (one reduction of two
  // doubles). Throws SolverFailure on a non-finite state (naming the step where a rank first saw it) or on
  // energy growth; runs the full check every `every` steps and whenever the kinetic energy exceeds twice the
  // largest kinetic energy of any earlier check.
  //
  // `whole` false: the solver's state is not at this whole step (a fused step that drifted on into the next one's
  // half kick; only the kinetic energy is of this step): a check this step needs (non-finite, growth) is not made
  // here but pending, and the solver must end the next step at its whole state (check_pending()) and call this
  // again, which then makes it, one step later (no step between the checks reads the state).
  //
  // `observed`: this step's state is written (a history row, snapshot or checkpoint follows): the reduction is
  // made now whatever the step, so that a non-finite state is reported, never written (1 reduction a row).
  void dynamic_step(double local_kinetic, bool whole = true, bool observed = false);
  // A check found due at a step that was not whole (above): the next step must be.
  bool check_pending() const { return pending_; }
  // Steps between the periodic full checks (their steps must be whole).
  long every() const { return every_; }
  // Relaxation, after every iteration with the (global) relative residual already reduced: no communication
  // unless a check is due. Throws SolverFailure on a non-finite or exploding residual.
  void relaxation_step(double residual);
  // Full check now (collective): finite state, connection lengths; keeps the state as the last good one.
  void full_check();
  // The same check of the state this guard was made at, nothing changed since (the static solver's final check):
  // the lengths from the constructor's connection pass (with `copy` false: one pass of its own, the only one),
  // and what it kept stays the last good state.
  void full_check_as_made();
  // Keeps the current state as the last good one (no checks).
  void keep();

  // Restores the last good state into the SolverState and throws SolverFailure with `problem` at `molecule`.
  [[noreturn]] void fail(const std::string& problem, std::int64_t molecule);

  // Called before the guard reads the state (x, v, f) at a whole step interlaced: a solver that keeps its state
  // in another layout between steps puts it back there (the dynamic solver's streams). Empty: nothing to do. The
  // periodic checks of dynamic_step read the streams as they are (SolverState::x_streams); a failure, a final
  // check and the relaxation's checks read the state interlaced.
  void on_read(std::function<void()> prepare) { prepare_ = std::move(prepare); }

  double kinetic_energy() const { return kinetic_; }
  bool enabled() const { return enabled_; }  // false: -tissue_guards false
  long checks() const { return checks_; }  // full checks made so far (energy and/or lengths)
  double seconds() const { return seconds_; }  // wall time spent inside the guard's calls so far
  long last_good_step() const { return good_step_; }

private:
  // Collective: whole-step total energy and its parts; the same pass over the connections finds the shortest one
  // relative to its rest length, which check_lengths(true) then uses instead of a second pass.
  double energy(double* spring, double* work);
  void check_lengths(bool from_energy = false);         // collective
  void check_finite_state();                            // collective
  void read_state() {
    if (prepare_) prepare_();
  }

  std::string solver_;
  const Scene& scene_;
  const LocalModel& model_;
  const ForceModel& forces_;
  SolverState& state_;
  long every_;
  double kinetic_ = 0.0, kinetic_checked_ = 0.0, energy0_ = 0.0;
  double residual0_ = -1.0;
  bool enabled_ = true;       // false with -tissue_guards false (benchmarks)
  bool copy_ = true;          // the last good state is a copy (false: the state itself, never changed here)
  bool energy_check_ = true;  // off when a term the energy does not account for is on (cyclic loads, contact)
  std::vector<double> good_x_, good_v_;
  long good_step_ = 0;
  long checks_ = 0;
  long first_bad_step_ = -1;  // dynamic: the first step this rank's kinetic energy was non-finite
  bool pending_ = false;      // dynamic: a check due at a step that was not whole (dynamic_step)
  std::string first_seen_;     // " (first non-finite kinetic energy at step S)", once the ranks compared notes
  double worst_ratio_ = 0.0;   // from energy(): the shortest connection's length / rest length on this rank
  double seconds_ = 0.0;
  double good_time_ = 0.0;
  std::function<void()> prepare_;
};

}  // namespace tissue
