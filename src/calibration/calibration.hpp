// Calibration: a stiffness k (N/m) per connection, chosen so the body has the material's Young's modulus.
// One file per method (the paper's section 3.3 and beyond), each a function plus one registry line in
// calibration.cpp. A method sees only this rank's connections and their end molecules (ghosts included).
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "io/scene.hpp"

namespace tissue {

struct LocalModel;
struct SolverState;
struct SolverHooks;
struct SolveReport;
struct TensionTest;
class ForceModel;

struct CalibrationContext {
  const Scene& scene;
  const LocalModel& model;
};

// Sets model.stiffness[c] for every local connection c.
using CalibrationFunction = void (*)(const CalibrationContext&, std::vector<double>& stiffness);

// Methods whose k follows the deformation (angles-update): makes, once per run, a refresher that sets
// stiffness[c] again from the current local positions x (3 * local values, ghosts up to date). The refresher is
// collective (every rank calls it at the same point) and owns whatever it caches; main() installs it as
// SolverHooks::refresh, which the relaxation (every iteration) and static (every Newton iteration) solvers call.
using CalibrationRefresher = std::function<void(const double* x)>;
using CalibrationUpdater = CalibrationRefresher (*)(const CalibrationContext&, std::vector<double>& stiffness);

struct CalibrationStyle {
  const char* name;
  CalibrationFunction compute;
  const char* description;
  CalibrationUpdater updater = nullptr;  // nullptr: k is fixed once calibrated
};

// Main's step 4: sets stiffness[c] for every local connection c by the method of the body it lies in
// (Scene::calibrations). One body: its method runs on the whole model, as it always has. Several: each body's
// method runs on a view of the model holding only that body's connections, with the body's geometry as the view's
// first body and the body's calibration as the view's scene.calibration, and its k are copied back. Returns the
// refreshers of the bodies whose method follows the deformation (angles-update), chained in body order (an empty
// function if none): install it as SolverHooks::refresh. Collective.
// Whether the stiffness stays as calibrated for the whole solve (no angles-update refresh, no iterative outer
// updates of C): then the connections can be stored by type (compact_connection_types).
bool stiffness_is_final(const Scene& scene, const CalibrationRefresher& refresh);

CalibrationRefresher calibrate_scene(const Scene& scene, const LocalModel& model, std::vector<double>& stiffness);

const std::vector<CalibrationStyle>& calibration_styles();
const CalibrationStyle* find_calibration(const std::string& name);
std::vector<std::string> calibration_method_names();

// Eq. 4 for one connection, k = E A / l0, with A and l0 the part of the body the connection stands for
// (see linear.cpp); the divided and iterative methods scale it.
double linear_stiffness(const LocalModel& model, int connection);
// The same on an explicit topology (mesh, random): A l0 = half the volume of the tetrahedra around the connection.
double linear_stiffness_tetrahedral(const LocalModel& model, int connection);

// The statistical method's estimated number of directions D among a molecule's N connections (statistical.cpp
// documents the reading of the paper's boundary cases N = 8, 12, 20).
double statistical_directions(int connections);

// The iterative method (iterative.cpp): wraps the solver. Repeats { k = linear / C; solve as the scene says;
// measure E (Eq. 3); C *= E_measured / E_target } until |E - target| / target < calibration.tolerance, filling
// `report` (the last solve's report plus calibration_divisor and calibration_updates). Throws SolverFailure when
// calibration.max_updates is reached; model.stiffness and state hold the last C's solution.
void solve_iterative(const Scene& scene, LocalModel& model, const ForceModel& forces, SolverState& state,
                     const SolverHooks& hooks, const TensionTest& test, SolveReport& report);

}  // namespace tissue
