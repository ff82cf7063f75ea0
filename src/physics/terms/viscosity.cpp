// Ambient viscous friction: -c v on every molecule ([physics] viscosity = c, N s/m per molecule). In the dynamic
// solver v is the half-step velocity of velocity Verlet.
#include "src/physics/term.hpp"

namespace tissue {

namespace {
class Viscosity final : public Term {
public:
  Viscosity(const LocalModel& m, double c) : m_(m), c_(c) {}
  void add_forces(const double*, const double* v, double, double* f) override {
    for (int i = 0; i < 3 * m_.owned; ++i) f[i] -= c_ * v[i];
  }

private:
  const LocalModel& m_;
  const double c_;
};
}  // namespace

std::unique_ptr<Term> make_viscosity(const TermContext& c) {
  return std::make_unique<Viscosity>(c.model, *c.scene.physics.viscosity);
}

TISSUE_TERM(viscosity, {"viscosity",
                        [](const Scene& s) { return s.physics.viscosity.has_value() && *s.physics.viscosity > 0; },
                        make_viscosity, "[physics] viscosity = c: ambient viscous friction -c v on every molecule", 20,
                        /*energy_never_grows=*/true, ContactReport::none, /*reads_velocity=*/true});

}  // namespace tissue
