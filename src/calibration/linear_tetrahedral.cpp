// Eq. 4, k = E A / l0, on an explicit topology (a mesh or a random cloud), where no lattice says which volume a
// connection stands for. Reading chosen: the volume of the median dual facet the connection crosses, as the box
// lattice's tributary prism is on the rectangular topology. Summed over a tetrahedron's 6 edges, the dual facets
// give A . l0 = 3 vol(T) (the lattice's edges too cover the volume once per axis); shared equally, as on a
// regular tetrahedron, each edge gets vol(T) / 2:
//     k = E (sum over incident tetrahedra of vol(T) / 2) / l0^2  =  Van Gelder's Eq. 5 / 2.
// On an isotropic network the tension test then reads about E / 2 (Eq. 5 is the exact isotropic average, nu = 1/4):
// the error docs/mesh.md measures. E per connection is the mean of its two end molecules' moduli.
#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"

namespace tissue {

double linear_stiffness_tetrahedral(const CalibrationContext& ctx, int c) {
  const LocalModel& m = ctx.model;
  const double E = 0.5 * (ctx.inputs.youngs_modulus[m.end_a[c]] + ctx.inputs.youngs_modulus[m.end_b[c]]);
  const double l0 = m.l0(c);
  return E * 0.5 * ctx.inputs.tetra_volume.at(c) / (l0 * l0);
}

}  // namespace tissue
