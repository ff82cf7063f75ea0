// The pipeline of src/main.cpp (stages 1-7 of src/driver/simulation.hpp) in process, for tests: scene text -> body
// -> partition -> calibration -> force model -> solve -> measure, with everything kept for the test to look at.
#pragma once
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

}  // namespace tissue::test_pipeline
