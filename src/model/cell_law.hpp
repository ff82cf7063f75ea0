// Any Poisson ratio on a box lattice (docs/poisson.md): the split of the isotropic target (E, nu) between the
// lattice's central springs and one per-cell energy of the cell-centre deformation gradient. Pure arithmetic on
// the cell's spacing and the material, shared by the homogenized calibration (the springs) and the cell term
// (src/physics/terms/cell_elasticity.cpp), so both read the same numbers.
//
// Springs alone obey the Cauchy relation: an isotropic set of them is the material (lambda = mu = s). The cell
// term carries the rest of the target:
//  - isotropic: mu_c = mu - s (isochoric) and kappa_c = K - 5 s / 3 (volumetric), with s = min(mu, 3K/5), so
//    both are >= 0 and at most one is non-zero (kappa_c for nu > 1/4, mu_c for nu < 1/4);
//  - on cells too far from cubic for an isotropic set of springs (h_a^2 / h_b^2 + h_a^2 / h_c^2 > 3 for some
//    axis a, with face diagonals), the diagonals are scaled down by a share w < 1 and the shear they no longer
//    carry, alpha = (1 - w) s per face plane, is carried by the cell as "virtual" diagonals at 45 degrees in that
//    plane's reference frame (a positive semi-definite orthotropic part, see cell_elasticity.cpp); the edges then
//    make the spring tensor plus that part exactly isotropic again.
#pragma once
#include <cmath>
#include <string>

#include "src/model/scene.hpp"
#include "src/model/topology.hpp"

namespace tissue {

// One cell's share, for a spring modulus E_s = 1 (the springs then carry lambda = mu = 0.4 E_s; everything scales
// with E_s). A connection's k is (cells it belongs to) x (its per-cell value) x E_s.
struct CellSprings {
  double edge[3] = {0, 0, 0};   // N/m per unit E_s, per cell, along axis a
  double face[3] = {0, 0, 0};   // diagonal of the face normal to axis w
  double body = 0;
  double alpha[3] = {0, 0, 0};  // Pa per unit E_s: the cell's virtual diagonals in the plane normal to axis w
  double share = 1.0;           // w: the diagonals' share of their isotropic value (1: cubic-like cells)
};
CellSprings cell_springs(const Vec3& h, CellFamilies families);

// The isotropic split of (E, nu) (nu NaN: absent, i.e. nu = 1/4 with E_s = E bit for bit and nothing in the cell).
struct CellModuli {
  double spring_modulus;  // E_s, Pa: the springs carry lambda = mu = 0.4 E_s
  double mu_c, kappa_c;   // Pa: the cell's isochoric and volumetric moduli
};
CellModuli cell_moduli(double youngs_modulus, double poisson_ratio);

// Does a body need the cell term: homogenized, a box lattice with diagonals, and a Poisson ratio other than 1/4
// somewhere or cells too far from cubic for isotropic springs.
bool body_has_cells(const BodySpec& body, const CalibrationSpec& calibration);
bool scene_has_cells(const Scene& scene);

// The P-wave modulus lambda + 2 mu of (E, nu) (nu NaN: 1/4).
inline double p_wave_modulus(double E, double nu) {
  if (std::isnan(nu)) nu = 0.25;
  return E * (1 - nu) / ((1 + nu) * (1 - 2 * nu));
}

}  // namespace tissue
