// The pipeline of src/main.cpp (stages 1-7 of src/driver/simulation.hpp) in process, for tests: scene text -> body
// -> partition -> calibration -> force model -> solve -> measure, with everything kept for the test to look at.
#pragma once
#include <mpi.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "io/gmsh_mesh.hpp"
#include "io/scene.hpp"
#include "src/driver/simulation.hpp"

namespace tissue::test_pipeline {

// The driver's stages (src/driver/simulation.hpp) with names for what a test looks at.
struct RunResult {
  explicit RunResult(std::unique_ptr<Simulation> s)
      : sim(std::move(s)), scene(sim->scene()), model(sim->model()), inputs(sim->calibration_inputs()), forces(&sim->forces()), state(&sim->state()),
        test(sim->test()), report(sim->report()), measured(sim->measured()), refresh(sim->refresh()) {}
  std::unique_ptr<Simulation> sim;
  Scene& scene;
  LocalModel& model;
  const CalibrationInputs& inputs;  // kept: the pipeline runs with keep_calibration_inputs
  ForceModel* forces;
  SolverState* state;
  TensionTest& test;
  SolveReport& report;
  Measurements& measured;
  CalibrationRefresher& refresh;
};

// `set`: --set overrides; solve only when `do_solve`; `before_solve` may change the start state. A solver failure
// is thrown, as the solvers throw it.
inline std::unique_ptr<RunResult> run(const std::string& text, MPI_Comm comm, const std::vector<std::string>& set = {},
                                      bool do_solve = true, std::function<void(RunResult&)> before_solve = nullptr) {
  Scene scene = parse_scene(text, "test.toml", set);
  scene.output.progress = false;
  auto sim = std::make_unique<Simulation>(std::move(scene), comm, Simulation::Options{/*keep_calibration_inputs=*/true});
  sim->build(read_mesh);
  sim->calibrate();
  sim->make_forces();
  auto r = std::make_unique<RunResult>(std::move(sim));
  if (before_solve) before_solve(*r);
  if (do_solve) {
    r->sim->solve(SolverHooks{});
    if (r->sim->outcome() == Simulation::Outcome::solver_failure)
      throw SolverFailure(r->sim->failure(), r->sim->failed_state());
  }
  r->sim->measure();
  return r;
}

// Every molecule's final position by global id (3 a molecule), gathered on every rank: what tests compare across
// rank counts, partitions and solvers.
inline std::vector<double> gather_positions(const RunResult& r) {
  std::vector<double> mine(3 * r.model.global_molecules, 0.0), all(mine.size());
  for (int i = 0; i < r.model.owned; ++i)
    for (int d = 0; d < 3; ++d) mine[3 * r.model.id[i] + d] = r.state->x.array()[3 * i + d];
  MPI_Allreduce(mine.data(), all.data(), static_cast<int>(mine.size()), MPI_DOUBLE, MPI_SUM, r.model.comm);
  return all;
}

}  // namespace tissue::test_pipeline
