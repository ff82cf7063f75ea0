#include "src/driver/simulation.hpp"

#include <chrono>
#include <utility>

#include "partition/agreement.hpp"

namespace tissue {

Simulation::Simulation(Scene scene, MPI_Comm comm, Options options)
    : scene_(std::move(scene)), comm_(comm), options_(options) {}

// Each stage is agreed (partition/agreement.hpp): what one rank throws at its end stops every rank there with the
// same line, before the next stage's collectives. (Inside a stage, the partitioning agrees on its own.)
void Simulation::build(const MeshReader& read_mesh) {
  agree(comm_, [&] {
    model_ = build_local_model(scene_, comm_, inputs_, read_mesh);
    test_ = tension_test(scene_, model_.shape);
    fault_point("build", comm_);
  });
  // The rest state's measurements, once (every summary reads them); collective, so after the stage agreed.
  agree(comm_, [&] { initial_ = tissue::measure(scene_, model_, test_, model_.rest.data(), nullptr); });
}

void Simulation::calibrate() {
  agree(comm_, [&] {
    refresh_ = calibrate_scene(scene_, model_, inputs_);
    fault_point("calibration", comm_);
  });
  agree(comm_, [&] {
    if (stiffness_is_final(scene_, refresh_)) {
      model_.table.compact();
      // Only calibration reads a connection's class: once k is final its byte a connection goes, as the inputs do.
      if (!options_.keep_calibration_inputs && !solver_wrapping_calibration(scene_))
        std::vector<ConnectionClass>().swap(model_.connection_class);
    }
    // Without k final there are no stencil segments, and ends stored as runs would cost a lookup a read: arrays.
    if (!model_.table.typed() && !model_.end_a.plain())
      model_.end_a.assign(model_.end_a.values()), model_.end_b.assign(model_.end_b.values());
    // A refresher (angles-update) took what it reads when it was made; a solver-wrapping method reads the inputs
    // at every update.
    if (!options_.keep_calibration_inputs && !solver_wrapping_calibration(scene_)) inputs_ = CalibrationInputs();
  });
}

void Simulation::make_forces() {
  agree(comm_, [&] {
    forces_ = std::make_unique<ForceModel>(scene_, model_);
    dt_critical_ = tissue::critical_time_step(*forces_);
    state_ = std::make_unique<SolverState>(model_);
  });
}

void Simulation::solve(SolverHooks hooks) {
  if (refresh_) hooks.refresh = refresh_;
  try {
    if (const CalibrationStyle* wrapper = solver_wrapping_calibration(scene_))
      wrapper->wrap_solver(scene_, model_, inputs_, *forces_, *state_, hooks, test_, report_);
    else
      report_ = tissue::solve(scene_, model_, *forces_, *state_, hooks);
    if (report_.interrupted) {
      outcome_ = Outcome::interrupted;
    } else if (!report_.converged) {
      outcome_ = Outcome::not_converged;
      failure_ = std::string(kind_name(report_)) + ": not converged after " + std::to_string(report_.iterations) +
                 " iterations (relative residual " + std::to_string(report_.residual) + ")";
    }
  } catch (const SolverFailure& e) {
    outcome_ = Outcome::solver_failure, failure_ = e.what(), failed_state_ = e.state();
    report_.kind = find_solver(scene_.solver.kind);
  }
}

void Simulation::measure() {
  measured_ = tissue::measure(scene_, model_, test_, state_->x.array(), state_->v.data(), 0, 0, state_->time);
  measure_contact(*forces_, measured_);  // the contact forces of the final state's force evaluation
  if (scene_.fixes.empty()) return;
  // The static solve's final evaluation was at this state with the full loads: its reactions, not a third
  // evaluation. A calibration wrapping the solver may change the stiffness after its last solve: evaluated.
  if (state_->forces_final && !solver_wrapping_calibration(scene_)) {
    measured_.reactions = forces_->last_reactions();
  } else {
    std::vector<double> scratch(3 * model_.local);  // the state's forces stay as the solve left them
    measured_.reactions = forces_->reactions(state_->x.array(), state_->v.data(), scratch.data());
  }
}

void Simulation::write(Output& out, double wall_seconds) {
  // wall_seconds runs to the end of the last write (../shared/interface.md): the final snapshot's time is added
  // to what the caller measured before it; only the summary's own few bytes are after the number it holds.
  const auto before = std::chrono::steady_clock::now();
  // A solver failure caught by the guards (src/solvers/guards.hpp) has put the last good state back into the
  // state: it is written as DIR/last_good.h5, never as final.h5. A non-finite state is not written at all.
  if (failed() && failed_state_ == SolverFailure::State::last_good)
    out.snapshot(*state_, *forces_, /*final=*/false, "last_good.h5");
  else if (outcome_ != Outcome::interrupted && failed_state_ == SolverFailure::State::finished)
    out.snapshot(*state_, *forces_, /*final=*/true);
  wall_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - before).count();
  out.summary(test_, measured_, initial_, report_, *state_, wall_seconds, failure_);
}

void Simulation::write_checkpoint_summary(Output& out, const SolverState& state, const std::string& checkpoint,
                                          double wall_seconds) {
  // (a dynamic run's state may be its three streams: measure() reads either layout)
  const Measurements now =
      tissue::measure(scene_, model_, test_, state.x.array(), state.v.data(), state.x_streams, state.v_streams,
                      state.time);
  SolveReport so_far;  // what is known before the solver returns: the kind, its steps, its time step
  so_far.kind = find_solver(scene_.solver.kind);
  so_far.iterations = state.step;
  so_far.time_step = state.time_step;
  so_far.critical_time_step = dt_critical_;
  so_far.running = true;
  so_far.note = "written with " + checkpoint + "; the run goes on";
  out.summary(test_, now, initial_, so_far, state, wall_seconds, "");
}

}  // namespace tissue
