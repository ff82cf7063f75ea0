// The pipeline of src/main.cpp (steps 1-7) in process, for tests: scene text -> body -> partition ->
// calibration -> force model -> solve -> measure, with everything kept for the test to look at.
#pragma once
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "io/scene.hpp"
#include "partition/local_model.hpp"
#include "partition/metis_partition.hpp"
#include "src/calibration/calibration.hpp"
#include "src/measure.hpp"
#include "src/model/body.hpp"
#include "src/solvers/solver.hpp"

namespace tissue::test_pipeline {

struct RunResult {
  Scene scene;
  LocalModel model;
  std::unique_ptr<ForceModel> forces;
  std::unique_ptr<SolverState> state;
  TensionTest test;
  SolveReport report;
  Measurements measured;
  CalibrationRefresher refresh;
};

// `set`: --set overrides; solve only when `do_solve`; `before_solve` may change the start state.
inline std::unique_ptr<RunResult> run(const std::string& text, MPI_Comm comm, const std::vector<std::string>& set = {},
                                      bool do_solve = true, std::function<void(RunResult&)> before_solve = nullptr) {
  auto r = std::make_unique<RunResult>();
  r->scene = parse_scene(text, "test.toml", set);
  r->scene.output.progress = false;
  r->model = build_local_model(r->scene, comm);
  r->test = tension_test(r->scene, r->model.shape);
  r->refresh = calibrate_scene(r->scene, r->model, r->model.stiffness);  // step 4 as main() does it
  if (stiffness_is_final(r->scene, r->refresh)) compact_connection_types(r->model);
  r->forces = std::make_unique<ForceModel>(r->scene, r->model);
  r->state = std::make_unique<SolverState>(r->model);
  if (before_solve) before_solve(*r);
  SolverHooks hooks;
  hooks.refresh = r->refresh;
  if (do_solve) r->report = solve(r->scene, r->model, *r->forces, *r->state, hooks);
  r->measured = measure(r->scene, r->model, r->test, r->state->x.array(), r->state->v.data());
  measure_contact(*r->forces, r->measured);
  return r;
}

}  // namespace tissue::test_pipeline
