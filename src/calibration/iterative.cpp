// The iterative solution: the divided method (k = linear k / C) with C adjusted by measurement until the tension
// test's Eq. 3 reads the target E. It wraps the solver: the driver calls solve_iterative() instead of solve().
//
//   C = calibration.divisor (start value); repeat { k = k_linear / C; solve as the scene says (static or
//   relaxation, warm-started from the previous equilibrium); E = Eq. 3; stop when |E - target| / target <
//   calibration.tolerance; C *= E / target }.
//
// The update is the fixed point of E ~ 1/C, exact for a linear response (the small-strain limit: one update),
// so the remaining updates only correct the geometric nonlinearity; calibration.max_updates bounds them and
// running out is a solver failure (exit 3). Note what this fits: the apparent modulus of the clamped test, which
// the clamp stiffens by ~2% in the continuum itself (reference/calibration.md), so on a clamped test the
// material it gives is ~2% too soft; with roller supports it fits the material.
#include <cmath>
#include <cstdio>
#include <string>

#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"
#include "src/measure/measure.hpp"
#include "src/physics/tension_test.hpp"
#include "src/solvers/solver.hpp"

namespace tissue {

void calibrate_iterative(const CalibrationContext& ctx, std::vector<double>& k) {
  if (!tension_test(ctx.scene, ctx.model.shape).valid)
    throw InputError(ctx.scene.file, "calibration.method",
                     "iterative needs a tension test: one [[load]] and a [[fix]] on the opposite face");
  if (!find_solver(ctx.scene.solver.kind)->equilibrium) {
    std::string kinds;
    for (const auto& s : solver_styles())
      if (s.equilibrium) kinds += std::string(kinds.empty() ? "" : " or ") + "\"" + s.name + "\"";
    throw InputError(ctx.scene.file, "calibration.method",
                     "iterative needs solver.kind = " + kinds + " (an equilibrium to measure), not \"" +
                         ctx.scene.solver.kind + "\"");
  }
  const double C = ctx.scene.calibration.divisor;
  for (int c = 0; c < ctx.model.connections(); ++c) k[c] = linear_stiffness(ctx, c) / C;
}

// Wraps the solver. Repeats { k = linear / C; solve as the scene says; measure E (Eq. 3); C *= E_measured /
// E_target } until |E - target| / target < calibration.tolerance, filling `report` (the last solve's report plus
// calibration_divisor and calibration_updates). Throws SolverFailure when calibration.max_updates is reached;
// the model's stiffness and the state hold the last C's solution.
void solve_iterative(const Scene& scene, LocalModel& model, const CalibrationInputs& inputs, const ForceModel& forces,
                     SolverState& state, const SolverHooks& hooks, const TensionTest& test, SolveReport& report) {
  const CalibrationContext ctx{scene, model, inputs};
  std::vector<double>& k = model.table.stiffness();
  const double target = scene.body.youngs_modulus;
  double C = scene.calibration.divisor;
  long iterations = 0, linear_iterations = 0;
  double seconds = 0.0, cpu_seconds = 0.0, guard_seconds = 0.0;
  long guard_checks = 0;
  std::string history;
  for (long update = 0;; ++update) {
    for (int c = 0; c < model.connections(); ++c) k[c] = linear_stiffness(ctx, c) / C;
    report = solve(scene, model, forces, state, hooks);
    iterations += report.iterations, linear_iterations += report.linear_iterations;
    report.iterations = iterations, report.linear_iterations = linear_iterations;
    seconds += report.seconds, report.seconds = seconds;  // every solve's
    cpu_seconds += report.cpu_seconds, report.cpu_seconds = cpu_seconds;
    guard_seconds += report.guard_seconds, report.guard_seconds = guard_seconds;
    guard_checks += report.guard_checks, report.guard_checks = guard_checks;
    report.calibration_divisor = C;
    report.calibration_updates = update;
    if (!report.converged) {
      report.note += "iterative calibration: the solve with C = " + std::to_string(C) + " did not converge. ";
      return;  // main() reports the unconverged solve
    }
    const Measurements measured = measure(scene, model, test, state.x.array(), nullptr);
    if (!measured.youngs_modulus) throw SolverFailure("iterative calibration: Eq. 3 cannot be measured");
    const double E = *measured.youngs_modulus, error = (E - target) / target;
    char line[96];
    std::snprintf(line, sizeof line, "C = %.10g: E error %+.3e; ", C, error);
    history += line;
    if (std::fabs(error) < scene.calibration.tolerance) {
      report.note += "iterative calibration: " + history;
      return;
    }
    if (update >= scene.calibration.max_updates)
      throw SolverFailure("iterative calibration: relative error in E still " + std::to_string(error) + " after " +
                          std::to_string(update) + " updates of C (calibration.max_updates; last C = " +
                          std::to_string(C) + ")");
    if (!(E > 0) || !std::isfinite(E))
      throw SolverFailure("iterative calibration: measured E = " + std::to_string(E) + " with C = " +
                          std::to_string(C) + ": cannot update C");
    C *= E / target;
  }
}

TISSUE_CALIBRATION(iterative, {"iterative", calibrate_iterative,
                               "C adjusted by measurement until Eq. 3 gives E (wraps the solver)", nullptr,
                               solve_iterative});

}  // namespace tissue
