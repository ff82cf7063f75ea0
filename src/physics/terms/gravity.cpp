// Gravity: m g on every molecule ([physics] gravity = [gx, gy, gz], m/s^2). Potential -m g . (x - x_rest).
#include "src/physics/term.hpp"

namespace tissue {

namespace {
class Gravity final : public Term {
public:
  Gravity(const LocalModel& m, const Vec3& g) : m_(m), g_(g) {}
  void add_forces(const double*, const double*, double, double* f) override {
    const double* mass = m_.mass.data();
    for (int i = 0; i < m_.owned; ++i)
      for (int d = 0; d < 3; ++d) f[3 * i + d] += mass[i] * g_[d];
  }
  double potential_energy(const double* x) const override {
    double e = 0;
    for (int i = 0; i < m_.owned; ++i)
      for (int d = 0; d < 3; ++d) e -= m_.mass[i] * g_[d] * (x[3 * i + d] - m_.rest[3 * i + d]);
    return e;
  }

private:
  const LocalModel& m_;
  const Vec3 g_;
};
}  // namespace

std::unique_ptr<Term> make_gravity(const TermContext& c) {
  return std::make_unique<Gravity>(c.model, *c.scene.physics.gravity);
}

TISSUE_TERM(gravity, {"gravity", [](const Scene& s) { return s.physics.gravity.has_value(); }, make_gravity,
                      "[physics] gravity = [gx, gy, gz]: m g on every molecule", 10, /*energy_never_grows=*/true});

}  // namespace tissue
