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

// Transverse isotropy (docs/anisotropy.md): the five constants split into an isotropic matrix (lambda_m, mu_m),
// carried as above by springs + the isotropic cell term, and three per-cell invariant terms of the fibre direction
// a (I4 = a.C a, I5 = a.C^2 a): fibre E_f/8 (I4 - 1)^2, fibre shear dG/2 (I5 - I4^2), coupling
// alpha/2 (I4 - 1)(J - 1). In the fibre frame (axis 1 = a) the TI tensor has C11, C12 = C13, C22 = C33, C23,
// C44 = (C22 - C23)/2 = G_T, C55 = C66 = G_L; the matrix gives lambda_m + 2 mu_m to C11, C22, lambda_m to C12,
// C23, mu_m to C44..C66; the fibre E_f to C11; the coupling 2 alpha to C11 and alpha to C12, C13; the fibre
// shear dG to C55, C66. Solved in turn: mu_m = G_T, lambda_m = C23, alpha = C12 - C23,
// E_f = C11 - lambda_m - 2 mu_m - 2 alpha, dG = G_L - G_T.
struct TransverseIsotropy {
  double E_L, E_T, nu_LT, nu_TT, G_L;
};
struct TiStiffness {  // fibre frame, Voigt
  double C11, C12, C22, C23, C44, C55;
};
TiStiffness ti_stiffness(const TransverseIsotropy& t);
// "" when (E_L, E_T, nu_LT, nu_TT, G_L) is a positive definite material whose matrix part the lattice can carry
// (bulk modulus K_m > 0), else the problem in words.
std::string ti_problem(const TransverseIsotropy& t);
struct FibreModuli {
  double E_m, nu_m;       // the isotropic matrix, for cell_moduli and the springs
  double E_f, dG, alpha;  // Pa: the fibre, fibre-shear and coupling terms
};
FibreModuli fibre_moduli(const TransverseIsotropy& t);
// The material's five constants: the body's E and nu (NaN: 1/4) are E_T and nu_TT; G_L defaults to G_T.
TransverseIsotropy transverse_isotropy(double youngs_modulus, double poisson_ratio, const FibreSpec& fibres);
// The body's Young's modulus along lattice axis `axis` (what a tension test along it targets): the scene's E, or
// with [body.fibres] the transversely isotropic material's, 1/E(n) = (1 - c^2)^2 / E_T + c^4 / E_L +
// c^2 (1 - c^2) (1/G_L - 2 nu_LT / E_L) with c = n . a (E_L along the fibres, E_T across them).
double youngs_modulus_along(const BodySpec& body, int axis);
// The largest eigenvalue of the TI tensor (Mandel form): an upper bound of rho c^2 for every wave.
double ti_stiffest_modulus(const TiStiffness& c);

// The isotropic split of a molecule's material: of (E, nu) itself, or with fibres of its matrix (E_m, nu_m).
CellModuli cell_moduli(double youngs_modulus, double poisson_ratio, const FibreSpec* fibres);

// Does a body need the cell term: homogenized, a box lattice with diagonals, and a Poisson ratio other than 1/4
// somewhere or cells too far from cubic for isotropic springs.
// (with fibres: always)
bool body_has_cells(const BodySpec& body, const CalibrationSpec& calibration);
bool scene_has_cells(const Scene& scene);
// Does a body need the per-tetrahedron term (src/physics/terms/tetrahedron_elasticity.cpp): homogenized on a
// mesh or a random cloud (the term then carries E, nu and the fibres; the springs are 0).
bool body_has_tetrahedra(const BodySpec& body, const CalibrationSpec& calibration);
bool scene_has_tetrahedra(const Scene& scene);

// The P-wave modulus lambda + 2 mu of (E, nu) (nu NaN: 1/4).
inline double p_wave_modulus(double E, double nu) {
  if (std::isnan(nu)) nu = 0.25;
  return E * (1 - nu) / ((1 + nu) * (1 - 2 * nu));
}

}  // namespace tissue
