#include "src/model/cell_law.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace tissue {

// Per cell (spacing h_x, h_y, h_z, volume V), from C_ijkl = (1/V) sum over the cell's springs k L^2 n_i n_j n_k n_l,
// with mu = 0.4 (E_s = 1, so that C11 = 3 mu, C12 = C44 = mu for an isotropic set); see
// src/calibration/homogenized.cpp for the derivation of the isotropic set. A diagonal family in the plane of
// axes a, b adds c to C_aabb (= C_abab) and c h_a^2 / h_b^2 to C_aaaa; a cubic cell's diagonals add as much to
// C_aaaa as to the C_aabb's, so the difference X_a = (their C_aaaa) - (their sum of C_aabb) is what a non-cubic
// cell's diagonals put on axis a beyond the cubic ones. Edges can only add to C_aaaa, which must total 3 mu:
// X_a <= mu is the isotropic range. Beyond it the diagonals get a share w < 1 and the cell the missing shear
// alpha = (1 - w) mu per plane as virtual 45-degree diagonals (C_aaaa = C_bbbb = C_aabb = C_abab = alpha); the
// edges fill C_aaaa to 3 mu: edge = mu - w X_a, positive for w < mu / max X_a.
CellSprings cell_springs(const Vec3& h, CellFamilies families) {
  CellSprings s;
  const double V = h[0] * h[1] * h[2];
  const double h2[3] = {h[0] * h[0], h[1] * h[1], h[2] * h[2]};
  if (families == CellFamilies::edges) {
    for (int a = 0; a < 3; ++a) s.edge[a] = V / (4.0 * h2[a]);
    return s;
  }
  const double mu = 0.4;
  const double Lb2 = h2[0] + h2[1] + h2[2];
  if (families == CellFamilies::body_diagonals) {
    const double t = 0.5;
    const double most = std::max({h2[0] * h2[1], h2[0] * h2[2], h2[1] * h2[2]});
    s.body = t * mu * V * Lb2 / (4.0 * most);
  }
  for (int w = 0; w < 3; ++w) {
    const int a = (w + 1) % 3, b = (w + 2) % 3;
    const double from_body = 4.0 * s.body * h2[a] * h2[b] / (Lb2 * V);
    s.face[w] = (mu - from_body) * V * (h2[a] + h2[b]) / (4.0 * h2[a] * h2[b]);
  }
  // The diagonals' C_aaaa per axis (they sum to mu on every C_aabb by construction).
  double diagonal[3];
  double worst = 0;
  for (int a = 0; a < 3; ++a) {
    diagonal[a] = 4.0 * s.body * h2[a] * h2[a] / (Lb2 * V);
    for (int b = 0; b < 3; ++b)
      if (b != a) diagonal[a] += 4.0 * s.face[3 - a - b] * h2[a] * h2[a] / ((h2[a] + h2[b]) * V);
    worst = std::max(worst, diagonal[a] - 2.0 * mu);
  }
  if (worst <= mu) {
    // Isotropic springs exist: today's set, computed as before (bit for bit).
    for (int a = 0; a < 3; ++a) {
      double rest = 3.0 * mu - 4.0 * s.body * h2[a] * h2[a] / (Lb2 * V);
      for (int b = 0; b < 3; ++b)
        if (b != a) rest -= 4.0 * s.face[3 - a - b] * h2[a] * h2[a] / ((h2[a] + h2[b]) * V);
      if (rest < 0) rest = 0;  // only round-off at the range's edge
      s.edge[a] = rest * V / (4.0 * h2[a]);
    }
    return s;
  }
  // w = mu / (2 X - mu): 1 at the range's edge (continuous), and the edges keep at least mu / 2 however flat the
  // cell (w = mu / X would leave them 0 there, and face diagonals alone split a simple cubic lattice into two
  // unconnected sublattices whose relative shift no one-point cell gradient sees).
  s.share = mu / (2.0 * worst - mu);
  s.body *= s.share;
  for (int w = 0; w < 3; ++w) s.face[w] *= s.share, s.alpha[w] = (1.0 - s.share) * mu;
  for (int a = 0; a < 3; ++a) {
    const double rest = std::max(0.0, mu - s.share * (diagonal[a] - 2.0 * mu));
    s.edge[a] = rest * V / (4.0 * h2[a]);
  }
  return s;
}

CellModuli cell_moduli(double E, double nu) {
  if (std::isnan(nu)) return {E, 0.0, 0.0};
  const double mu = E / (2.0 * (1.0 + nu));
  const double lambda = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
  const double K = lambda + 2.0 * mu / 3.0;
  const double s = std::min(mu, 0.6 * K);
  return {s / 0.4, std::max(0.0, mu - s), std::max(0.0, K - 5.0 * s / 3.0)};
}

CellModuli cell_moduli(double E, double nu, const FibreSpec* fibres) {
  if (!fibres) return cell_moduli(E, nu);
  const FibreModuli f = fibre_moduli(transverse_isotropy(E, nu, *fibres));
  return cell_moduli(f.E_m, f.nu_m);
}

TiStiffness ti_stiffness(const TransverseIsotropy& t) {
  const double e = t.E_T / t.E_L;
  const double delta = 1.0 - t.nu_TT - 2.0 * t.nu_LT * t.nu_LT * e;
  TiStiffness c;
  c.C11 = t.E_L * (1.0 - t.nu_TT) / delta;
  c.C12 = t.E_T * t.nu_LT / delta;
  c.C22 = t.E_T * (1.0 - t.nu_LT * t.nu_LT * e) / ((1.0 + t.nu_TT) * delta);
  c.C23 = t.E_T * (t.nu_TT + t.nu_LT * t.nu_LT * e) / ((1.0 + t.nu_TT) * delta);
  c.C44 = 0.5 * t.E_T / (1.0 + t.nu_TT);
  c.C55 = t.G_L;
  return c;
}

std::string ti_problem(const TransverseIsotropy& t) {
  char buf[256];
  if (!(t.E_L > 0 && t.E_T > 0 && t.G_L > 0)) return "E_L, E_T and G_L must be > 0";
  if (!(t.nu_TT > -1.0 && t.nu_TT < 1.0)) {
    std::snprintf(buf, sizeof buf, "nu_TT = %g (the body's poisson_ratio) must be in (-1, 1)", t.nu_TT);
    return buf;
  }
  // The normal compliance block is positive definite iff also (1 - nu_TT) - 2 nu_LT^2 E_T / E_L > 0.
  const double d = 1.0 - t.nu_TT - 2.0 * t.nu_LT * t.nu_LT * t.E_T / t.E_L;
  if (!(d > 0)) {
    std::snprintf(buf, sizeof buf,
                  "not a positive definite material: 1 - nu_TT - 2 nu_LT^2 E_T / E_L = %g must be > 0 (nu_LT = %g, "
                  "nu_TT = %g, E_T / E_L = %g)",
                  d, t.nu_LT, t.nu_TT, t.E_T / t.E_L);
    return buf;
  }
  const TiStiffness c = ti_stiffness(t);
  const double K_m = c.C23 + 2.0 * c.C44 / 3.0;
  if (!(K_m > 0)) {
    std::snprintf(buf, sizeof buf,
                  "the isotropic matrix part lambda_m = C23 = %g Pa, mu_m = G_T = %g Pa has bulk modulus %g <= 0: "
                  "springs cannot carry it (raise nu_TT or lower nu_LT)",
                  c.C23, c.C44, K_m);
    return buf;
  }
  return "";
}

FibreModuli fibre_moduli(const TransverseIsotropy& t) {
  const TiStiffness c = ti_stiffness(t);
  const double mu = c.C44, lambda = c.C23;
  FibreModuli f;
  f.E_m = mu * (3.0 * lambda + 2.0 * mu) / (lambda + mu);
  f.nu_m = lambda / (2.0 * (lambda + mu));
  f.alpha = c.C12 - lambda;
  f.E_f = c.C11 - lambda - 2.0 * mu - 2.0 * f.alpha;
  f.dG = c.C55 - mu;
  return f;
}

TransverseIsotropy transverse_isotropy(double E, double nu, const FibreSpec& fibres) {
  if (std::isnan(nu)) nu = 0.25;
  TransverseIsotropy t{fibres.youngs_modulus, E, fibres.poisson_ratio, nu, 0.0};
  t.G_L = fibres.shear_modulus ? *fibres.shear_modulus : 0.5 * E / (1.0 + nu);
  return t;
}

double youngs_modulus_along(const BodySpec& body, int axis) {
  if (!body.fibres || axis < 0 || axis > 2) return body.youngs_modulus;
  const TransverseIsotropy t = transverse_isotropy(body.youngs_modulus, body.poisson_ratio.value_or(0.25), *body.fibres);
  const Vec3& a = body.fibres->direction;
  const double c2 = a[axis] * a[axis] / (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]), s2 = 1.0 - c2;
  return 1.0 / (s2 * s2 / t.E_T + c2 * c2 / t.E_L + c2 * s2 * (1.0 / t.G_L - 2.0 * t.nu_LT / t.E_L));
}

double ti_stiffest_modulus(const TiStiffness& c) {
  // Normal block: the transverse antisymmetric mode C22 - C23, and the 2 x 2 block [[C11, sqrt2 C12],
  // [sqrt2 C12, C22 + C23]]; shears (Mandel) 2 C44, 2 C55.
  const double m = 0.5 * (c.C11 + c.C22 + c.C23);
  const double r = std::sqrt(0.25 * (c.C11 - c.C22 - c.C23) * (c.C11 - c.C22 - c.C23) + 2.0 * c.C12 * c.C12);
  return std::max({m + r, c.C22 - c.C23, 2.0 * c.C44, 2.0 * c.C55});
}

bool body_has_cells(const BodySpec& body, const CalibrationSpec& calibration) {
  if (!calibration.honours_poisson || body.unstructured()) return false;
  const TopologyStyle* lattice = find_topology(body.topology);
  if (!lattice || !lattice->carries_poisson()) return false;
  if (body.has_fibres()) return true;
  if (body.poisson_ratio && *body.poisson_ratio != 0.25) return true;
  for (const auto& r : body.regions)
    if (r.poisson_ratio && *r.poisson_ratio != 0.25) return true;
  return cell_springs(body.spacing, lattice->cells).share < 1.0;
}

bool scene_has_cells(const Scene& scene) {
  if (scene.bodies.empty()) return !scene.calibrations.empty() && body_has_cells(scene.body, scene.calibrations[0]);
  for (std::size_t b = 0; b < scene.bodies.size(); ++b)
    if (body_has_cells(scene.bodies[b], b < scene.calibrations.size() ? scene.calibrations[b] : scene.calibration))
      return true;
  return false;
}

bool body_has_tetrahedra(const BodySpec& body, const CalibrationSpec& calibration) {
  return calibration.honours_poisson && body.unstructured();
}

bool scene_has_tetrahedra(const Scene& scene) {
  if (scene.bodies.empty())
    return !scene.calibrations.empty() && body_has_tetrahedra(scene.body, scene.calibrations[0]);
  for (std::size_t b = 0; b < scene.bodies.size(); ++b)
    if (body_has_tetrahedra(scene.bodies[b], b < scene.calibrations.size() ? scene.calibrations[b] : scene.calibration))
      return true;
  return false;
}

}  // namespace tissue
