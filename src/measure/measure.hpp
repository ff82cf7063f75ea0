// What a run measures: Eq. 3 (the body's Young's modulus from its elongation), the Poisson ratio, the centre of
// mass and the kinetic energy. Every value is a global reduction over the owned molecules.
#pragma once
#include <array>
#include <optional>
#include <vector>

#include "partition/local_model.hpp"
#include "src/physics/force_model.hpp"
#include "src/physics/tension_test.hpp"

namespace tissue {

struct Measurements {
  std::optional<double> elongation;        // m: mean displacement along the load, loaded face minus fixed face
  std::optional<double> youngs_modulus;    // Eq. 3: F l0 / (dl A), F the load at the measured time (none at F = 0)
  std::optional<double> applied_force;     // N: that F (the load's force times its history factor)
  std::optional<double> poisson_ratio;     // lateral contraction / axial strain, when lateral faces are free
  // The same per lateral axis, (axis + 1) % 3 and (axis + 2) % 3: both differ on an anisotropic body.
  std::optional<std::array<double, 2>> poisson_ratios;
  // The mean lateral strain of the same faces (the change of distance between the two faces of each lateral axis
  // over that distance, averaged over both axes; negative in contraction): history.csv's lateral_strain.
  std::optional<double> lateral_strain;
  // Simple shear: a clamped face and a tangential load on the face opposite: G = (F / A) / gamma, gamma the mean
  // displacement along F of the loaded face relative to the clamped one over their distance.
  std::optional<double> shear_modulus;
  // Confined compression: the tension test with all four lateral faces held in their normal (rollers): H_A =
  // F l0 / (dl A), reported instead of youngs_modulus.
  std::optional<double> aggregate_modulus;
  Vec3 center_of_mass{};
  double kinetic_energy = 0.0;
  double mass = 0.0;
  std::optional<Vec3> contact_force;      // total force the obstacles exert on the bodies (scenes with obstacles)
  std::vector<Vec3> body_contact_force;   // per body: force molecules of other bodies exert on it ([physics] contact)
  std::vector<Vec3> reactions;            // per [[fix]], scene order: the total force the hold exerts on the body
};

// x: local positions (owned first); v: owned velocities, or nullptr. x_streams, v_streams: 0 (interlaced,
// component d of molecule i at [3 i + d]) or the stride of three streams ([d * stride + i]: SolverState's).
// time: the state's (s), where the load has a history; Eq. 3 reads the load applied then.
Measurements measure(const Scene& scene, const LocalModel& model, const TensionTest& test, const double* x,
                     const double* v, std::size_t x_streams = 0, std::size_t v_streams = 0, double time = 0.0);
// Collective: the contact forces of the force model's last evaluation (its state after the solve) into m.
void measure_contact(const ForceModel& forces, Measurements& m);

}  // namespace tissue
