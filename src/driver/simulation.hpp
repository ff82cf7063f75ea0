// One run of the molecular model, stage by stage: what `tissue run` and `tissue restart` do (src/main.cpp), and
// what the tests drive in process (tests/pipeline.hpp), so the pipeline is written once. Every stage is
// collective: every rank calls it, in this order.
//
//   Simulation sim(scene, comm);   // 1. the scene, read and checked (io/scene.hpp)
//   sim.build(read_mesh);          // 2-3. this rank's molecules, ghosts and connections (partition/)
//   sim.calibrate();               // 4. a stiffness per connection (src/calibration/)
//   sim.make_forces();             // 5. the force model and the critical time step (src/physics/)
//   sim.solve(hooks);              // 6. equilibrium or time integration (src/solvers/); failures kept, not thrown
//   sim.measure();                 // 7. Eq. 3, Poisson ratio, centre of mass, kinetic energy (src/measure/)
//   sim.write(output, seconds);    // 8. final.h5 (or last_good.h5) and summary.json (io/)
#pragma once
#include <mpi.h>

#include <memory>
#include <string>

#include "io/output.hpp"
#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"
#include "src/measure/measure.hpp"
#include "src/model/unstructured.hpp"
#include "src/physics/force_model.hpp"
#include "src/physics/tension_test.hpp"
#include "src/solvers/solver.hpp"

namespace tissue {

class Simulation {
public:
  struct Options {
    // Keep the calibration inputs (each molecule's E and degree, ...) once the stiffness is final (tests read
    // them); a run drops them.
    bool keep_calibration_inputs = false;
  };

  Simulation(Scene scene, MPI_Comm comm, Options options);
  Simulation(Scene scene, MPI_Comm comm) : Simulation(std::move(scene), comm, Options{}) {}

  // 2-3. This rank's share of the bodies: METIS (or PT-Scotch) partitions the connection graph; each rank keeps its
  //      molecules, their ghosts and their connections, with material and mass per molecule. Box lattices are
  //      generated rank by rank from the topology's stencil; mesh bodies come from `read_mesh`.
  void build(const MeshReader& read_mesh);
  // 4. A stiffness per connection, each body by its own calibration method. A stiffness that no longer changes is
  //    stored by connection type (2 bytes a connection instead of 16) and what only calibration reads goes.
  void calibrate();
  // 5. The force model (connection forces plus only the terms the scene lists; loads and holds) and the critical
  //    time step of explicit integration.
  void make_forces();
  // 6. Solve as the scene says, from the state in state() (a restart loads it first). A calibration method that
  //    wraps the solver (iterative) runs it. A SolverFailure is caught: failed() and failure() tell, and
  //    failed_state() what the state holds.
  void solve(SolverHooks hooks);
  // 7. What the run measures, of the final state and of the rest state.
  void measure();
  // 8. The final state (final.h5; last_good.h5 when the guards put the last good state back; nothing when it is
  //    not finite or the run was interrupted) and summary.json.
  void write(Output& out, double wall_seconds);
  // At each checkpoint of step 6 (collective): summary.json of the state the checkpoint holds, "running": true, so
  // that a job killed later (a node lost, a time limit without warning) leaves the summary of its newest checkpoint
  // beside it (../shared/interface.md). Step 8's summary replaces it.
  void write_checkpoint_summary(Output& out, const SolverState& state, const std::string& checkpoint,
                                double wall_seconds);

  const Scene& scene() const { return scene_; }
  Scene& scene() { return scene_; }
  LocalModel& model() { return model_; }
  const CalibrationInputs& calibration_inputs() const { return inputs_; }
  const TensionTest& test() const { return test_; }
  TensionTest& test() { return test_; }
  CalibrationRefresher& refresh() { return refresh_; }
  ForceModel& forces() { return *forces_; }
  SolverState& state() { return *state_; }
  SolveReport& report() { return report_; }
  Measurements& measured() { return measured_; }
  const Measurements& initial() const { return initial_; }
  double critical_time_step() const { return dt_critical_; }
  // How the solve ended: finished (converged, or a dynamic run's last step), interrupted by a signal after a
  // checkpoint, not converged within its iterations, or a SolverFailure (diverged, non-finite, ...).
  enum class Outcome { finished, interrupted, not_converged, solver_failure };
  Outcome outcome() const { return outcome_; }
  bool failed() const { return outcome_ == Outcome::not_converged || outcome_ == Outcome::solver_failure; }
  const std::string& failure() const { return failure_; }
  SolverFailure::State failed_state() const { return failed_state_; }

private:
  Scene scene_;
  MPI_Comm comm_;
  Options options_;
  LocalModel model_;
  CalibrationInputs inputs_;  // made by build(), read by calibrate() (and a solver-wrapping method), then dropped
  TensionTest test_;
  CalibrationRefresher refresh_;
  std::unique_ptr<ForceModel> forces_;
  std::unique_ptr<SolverState> state_;
  SolveReport report_;
  Measurements measured_, initial_;
  double dt_critical_ = 0.0;
  Outcome outcome_ = Outcome::finished;
  std::string failure_;  // what failed, in words (empty unless failed())
  SolverFailure::State failed_state_ = SolverFailure::State::finished;
};

}  // namespace tissue
