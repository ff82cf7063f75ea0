// Calibration: a stiffness k (N/m) per connection, chosen so the body has the material's Young's modulus.
// One file per method (the paper's section 3.3 and beyond): its function and, in the same file, its registration
// line TISSUE_CALIBRATION(id, {...}); CMake lists those lines in a generated file that calibration.cpp reads, so a
// new method is one new file and nothing else (README, "Adding a calibration method"). A method sees only this
// rank's connections and their end molecules (ghosts included).
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "src/model/scene.hpp"

namespace tissue {

struct LocalModel;
struct CalibrationInputs;
struct SolverState;
struct SolverHooks;
struct SolveReport;
struct TensionTest;
class ForceModel;

struct CalibrationContext {
  const Scene& scene;
  const LocalModel& model;
  const CalibrationInputs& inputs;  // each molecule's E and degree, tetrahedra per connection (dropped after)
};

// Sets stiffness[c] for every local connection c.
using CalibrationFunction = void (*)(const CalibrationContext&, std::vector<double>& stiffness);

// Methods whose k follows the deformation (angles-update): makes, once per run, a refresher that sets
// stiffness[c] again from the current local positions x (3 * local values, ghosts up to date). The refresher is
// collective (every rank calls it at the same point) and owns whatever it caches; main() installs it as
// SolverHooks::refresh, which the relaxation (every iteration) and static (every Newton iteration) solvers call.
using CalibrationRefresher = std::function<void(const double* x)>;
using CalibrationUpdater = CalibrationRefresher (*)(const CalibrationContext&, std::vector<double>& stiffness);

// Methods that wrap the solver (iterative): run the solve themselves, adjusting the stiffness between solves, and
// fill `report`. The driver calls this instead of solve(). One-body scenes only (the scene reader checks).
using CalibrationSolver = void (*)(const Scene&, LocalModel&, const CalibrationInputs&, const ForceModel&, SolverState&,
                                   const SolverHooks&, const TensionTest&, SolveReport&);

// What a method needs of a body's topology; the scene reader checks it (the error names calibration.method).
enum class CalibrationNeeds {
  any_topology,
  tetrahedra,    // a tetrahedral topology (TopologyStyle::tetrahedra), a mesh or a random cloud: Eq. 5 sums over them
  lattice_cells, // a box lattice without tetrahedra (the method solves each cell's springs), or a mesh or random cloud
};

// A calibration method and what it can do; the driver and the scene reader ask these capabilities, never the
// method's name.
struct CalibrationStyle {
  const char* name;
  CalibrationFunction compute;
  const char* description;
  CalibrationUpdater updater = nullptr;      // not null: k follows the deformation (refreshed during the solve)
  CalibrationSolver wrap_solver = nullptr;   // not null: the method wraps the solver (one-body scenes)
  CalibrationNeeds needs = CalibrationNeeds::any_topology;
  bool reads_divisor = false;                // calibration.divisor is C as given (the summary reports it)
  bool honours_poisson = false;              // builds the body's Poisson ratio (else nu = 1/4: central springs)
  bool reads_stiffness = false;              // k as given per connection class (calibration.stiffness, required)
  // The stiffness stays as calibrated for the whole solve: the connections may be stored by type.
  bool stiffness_final() const { return !updater && !wrap_solver; }
};

// Registers a method, in its own file: TISSUE_CALIBRATION(angles_update, {"angles-update", ...}). `id` is a C++
// name (the scene's name may hold '-').
#define TISSUE_CALIBRATION(id, ...) \
  const CalibrationStyle& calibration_style_##id() {           \
    static const CalibrationStyle style __VA_ARGS__;          \
    return style;                                              \
  }

// Main's step 4: sets the model's stiffness k(c) for every local connection c by the method of the body it lies in
// (Scene::calibrations). One body: its method runs on the whole model, as it always has. Several: each body's
// method runs on a view of the model holding only that body's connections, with the body's geometry as the view's
// first body and the body's calibration as the view's scene.calibration, and its k are copied back. Returns the
// refreshers of the bodies whose method follows the deformation (angles-update), chained in body order (an empty
// function if none): install it as SolverHooks::refresh. Collective.
// Whether the stiffness stays as calibrated for the whole solve (every body's method has stiffness_final()): then
// the connections can be stored by type (ConnectionTable::compact).
bool stiffness_is_final(const Scene& scene, const CalibrationRefresher& refresh);
// The method that wraps the solver for this scene (body 0's, iterative), or nullptr: the driver solves.
const CalibrationStyle* solver_wrapping_calibration(const Scene& scene);
// Why `style` cannot calibrate a body of topology `topology` ("" when it can): for the scene reader's message.
std::string calibration_topology_problem(const CalibrationStyle& style, const std::string& topology);

CalibrationRefresher calibrate_scene(const Scene& scene, LocalModel& model, const CalibrationInputs& inputs);

// Every registered method, in the order of their files' names. find_calibration returns nullptr for an unknown name.
const std::vector<CalibrationStyle>& calibration_styles();
const CalibrationStyle* find_calibration(const std::string& name);
std::vector<std::string> calibration_method_names();

// Eq. 4 for one connection, k = E A / l0, with A and l0 the part of the body the connection stands for
// (see linear.cpp); the divided and iterative methods scale it.
double linear_stiffness(const CalibrationContext& ctx, int connection);
// The same on an explicit topology (mesh, random): A l0 = half the volume of the tetrahedra around the connection.
double linear_stiffness_tetrahedral(const CalibrationContext& ctx, int connection);

// The statistical method's estimated number of directions D among a molecule's N connections (statistical.cpp
// documents the reading of the paper's boundary cases N = 8, 12, 20).
double statistical_directions(int connections);


}  // namespace tissue
