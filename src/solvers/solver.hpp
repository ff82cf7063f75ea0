// Solvers: bring the body to equilibrium (static, relaxation) or integrate it in time (dynamic). All are driven
// by the ForceModel and advance a SolverState; the kind is chosen by `solver.kind`.
#pragma once
#include <csignal>
#include <functional>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "partition/agreement.hpp"
#include "partition/ghosted_vector.hpp"
#include "src/physics/force_model.hpp"

namespace tissue {

// The solver failed (diverged, not converged, NaN): the driver reports it and exits 3. `state` says what the
// SolverState holds afterwards, which decides what the driver writes. The ranks throw it together (they decide
// from reduced values): Collective, so that an agreed stage lets it pass with its state (partition/agreement.hpp).
class SolverFailure : public std::runtime_error, public Collective {
public:
  enum class State {
    finished,   // the failed solve's own state, finite: written as final.h5
    last_good,  // the guards (or the last converged load step) put the last good state back: last_good.h5
    nothing,    // nothing worth writing: a non-finite state, or no earlier state kept (-tissue_guards false)
  };
  explicit SolverFailure(const std::string& what, State state = State::finished)
      : std::runtime_error(what), state_(state) {}
  State state() const { return state_; }

private:
  State state_;
};

struct SolverState {
  explicit SolverState(const LocalModel& model)
      : x(model), v(3 * model.owned, 0.0), f(3 * model.local, 0.0) {
    for (int i = 0; i < 3 * model.local; ++i) x.array()[i] = model.rest[i];
  }
  GhostedVector x;        // positions, ghosts included
  std::vector<double> v;  // velocities of owned molecules
  std::vector<double> f;  // forces (3 * local; ghost slots are scratch)
  long step = 0;          // iterations or time steps done
  double time = 0.0;      // s, dynamic runs
  double time_step = 0.0; // s, the explicit solvers' step
  // What a checkpoint carries besides positions and velocities, so that a restart continues bit for bit.
  double divisor = 1.0;          // calibration: C of the divided and iterative methods
  long calibration_updates = 0;  // iterative: updates of C made
  double fire_dt = 0.0, fire_alpha = 0.0;  // relaxation: FIRE's adaptive step and mixing
  long fire_positive = 0;                  // relaxation: steps since the power was last negative
  double energy_initial = std::numeric_limits<double>::quiet_NaN();  // dynamic: the run's step-0 total energy
  bool restarted = false;                  // loaded from a checkpoint
  double load_factor = 1.0;  // static: the fraction of the loads the last converged load step reached
  // Static: the last ForceModel::forces() call was at x and v with the full loads (load factor 1) and nothing has
  // moved since, so forces.last_reactions() are the reactions there (no second evaluation for them).
  bool forces_final = false;
  // Dynamic runs whose forces read velocities (viscosity): the half-step velocities (owned) that the last force
  // evaluation read; empty otherwise. A checkpoint keeps them: velocity Verlet's forces at step n read
  // v(n - 1/2), not the whole-step v(n) that the checkpoint's velocities hold.
  std::vector<double> v_half;
  // The dynamic solver keeps x, v and f as three streams each between steps (component d of molecule i at
  // x[d * x_streams + i], v[d * v_streams + i], f[d * x_streams + i]). Nonzero only while its history rows and
  // its guard's periodic checks read the state in that layout (measure() and StepGuard take either); 0:
  // interlaced (3 i + d), what everything else reads (a snapshot or checkpoint gets the state interlaced).
  std::size_t x_streams = 0, v_streams = 0;
};

struct SolverStyle;

struct SolveReport {
  const SolverStyle* kind = nullptr;  // the kind that ran (solve() sets it); nullptr: none ran
  long iterations = 0;          // relaxation iterations, Newton iterations or time steps
  long linear_iterations = 0;   // static: Krylov iterations, summed
  double residual = 0.0;        // final relative force residual (static, relaxation)
  double tolerance_used = 0.0;  // solver.tolerance, or the round-off floor when that is higher
  bool converged = false;
  std::vector<double> residual_history;  // one per Newton iteration, or sampled relaxation iterations
  double time_step = 0.0, critical_time_step = 0.0;
  double energy_initial = 0.0, energy_final = 0.0;  // dynamic: total energy (see dynamic.cpp)
  std::string note;             // fall-backs taken, in words
  std::optional<double> calibration_divisor;  // iterative calibration: the final C (else absent)
  long calibration_updates = 0;                // iterative calibration: updates of C made
  bool interrupted = false;                    // stopped by a signal after writing a checkpoint
  bool running = false;  // a summary written at a checkpoint: the solve goes on (Simulation::write_checkpoint_summary)
  double seconds = 0.0;      // wall time of the solve alone (rank 0's; no set-up, calibration or output)
  double cpu_seconds = 0.0;  // CPU time of rank 0's process over the same span
  long guard_checks = 0;     // relaxation, dynamic: full guard checks made (each about one force evaluation)
  double guard_seconds = 0.0;  // relaxation, dynamic: rank 0's wall time inside the guards (of `seconds`)
};

struct SolverHooks {
  std::function<void(const SolverState&)> snapshot;  // called every output.snapshot_every steps
  // Calibrations that follow the deformation (angles-update): called with the local positions (ghosts up to date)
  // every relaxation iteration and at the start of every Newton iteration, to refresh the model's stiffness. Collective.
  std::function<void(const double* x)> refresh;
  // Writes a checkpoint of the state (collective); called every output.checkpoint_every steps and when a stop
  // is requested.
  std::function<void(const SolverState&)> checkpoint;
  // DIR/history.csv's rows (collective), with the state at a step's end: quasi-static after every step, the
  // t = 0 step included; dynamic at step 0 and every output.history_every steps; static after every load step;
  // relaxation once, at its end.
  std::function<void(const SolverState&)> record;
};

// Set by the SIGTERM/SIGINT handler that main() installs: the solvers write a checkpoint at the next step
// boundary and return with SolveReport::interrupted.
extern volatile std::sig_atomic_t stop_requested;
// At a step boundary: writes a checkpoint when one is due; returns true when the run must stop (a signal arrived
// on any rank; checked every `every` steps, a collective reduction).
bool step_boundary(const Scene& scene, const LocalModel& model, const SolverState& state, const SolverHooks& hooks,
                   long every);

// The critical time step of explicit integration: 2 / sqrt(max eigenvalue of M^-1 K), bounded by Gershgorin.
double critical_time_step(const ForceModel& forces);

// The tolerance a solve can reach: solver.tolerance, raised (with a message on rank 0) to twice the round-off floor
// of the relative residual, eps |sum over connections of k l| per molecule over the applied forces: spring forces
// are differences of lengths, so each carries an error of about eps k l. Collective.
double reachable_tolerance(const Scene& scene, const LocalModel& model, const ForceModel& forces);
// The same against any reference (N): `tolerance` (relative) raised to round_off / reference (a warning on rank 0
// when `warn`), and a SolverFailure naming `what` (the forces the reference stands for) when that floor is above
// 1e-3. Not collective: every rank passes the same numbers.
double reachable_tolerance(double tolerance, double round_off, double reference, const char* what, int rank,
                           bool warn);
// The round-off of the force residual (N): 2 eps |sum over connections of k l| per molecule, 2-norm. Collective.
double force_round_off(const LocalModel& model, const ForceModel& forces);

// Relative force residual: |F on free components| / |applied forces| (global), from f of every owned molecule.
double relative_residual(const LocalModel& model, const ForceModel& forces, const double* f);
// Throws SolverFailure naming the step and the molecule when a force or position is not finite.
void check_finite(const LocalModel& model, const double* x, const double* f, long step, const char* what);

using SolveFunction = SolveReport (*)(const Scene&, const LocalModel&, const ForceModel&, SolverState&,
                                      const SolverHooks&);

// A solver kind (solver.kind) and what it can do; the scene reader, the calibration and the summary ask these
// capabilities, never the kind's name. Each kind is one file holding its solve function and its registration
// line TISSUE_SOLVER(id, {...}) (CMake lists those lines in a generated file that solver.cpp reads).
struct SolverStyle {
  const char* name;
  SolveFunction solve;
  const char* description;
  bool equilibrium = false;           // finds a static equilibrium (the iterative calibration measures it)
  bool newton = false;                // Newton-Krylov on the assembled tangent: Krylov iterations are reported
  bool explicit_steps = false;        // steps with a time step (solver.time_step) under the per-step guards
  bool integrates_time = false;       // follows the motion in time: cyclic loads; rigid motion need not be held
  bool settles_on_obstacles = false;  // an equilibrium may be held by obstacles alone (never inverts the stiffness)
  bool time_line = false;             // advances a time line: time and steps in the summary
  bool moves_holds = false;           // holds may move (fix displacement, history): equilibrium at every time
  bool needs_time_step = false;       // solver.time_step must be given (no critical step to start from)
  bool checkpointed = true;           // output.checkpoint_every is honoured (restart resumes the run)
};

// The name of the kind that ran ("" when none did: a failure before the solve).
inline const char* kind_name(const SolveReport& report) { return report.kind ? report.kind->name : ""; }

#define TISSUE_SOLVER(id, ...)                    \
  const SolverStyle& solver_style_##id() {        \
    static const SolverStyle style __VA_ARGS__;  \
    return style;                                 \
  }

// Every registered solver kind, in the order of their files' names; find_solver returns nullptr for an unknown name.
const std::vector<SolverStyle>& solver_styles();
const SolverStyle* find_solver(const std::string& name);
std::vector<std::string> solver_names();

// Solves as the scene's solver.kind says (its SolverStyle's solve), timing it.
SolveReport solve(const Scene&, const LocalModel&, const ForceModel&, SolverState&, const SolverHooks&);

}  // namespace tissue
