#include "src/model/cell_law.hpp"

#include <algorithm>
#include <cmath>

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

bool body_has_cells(const BodySpec& body, const CalibrationSpec& calibration) {
  if (!calibration.honours_poisson || body.unstructured()) return false;
  const TopologyStyle* lattice = find_topology(body.topology);
  if (!lattice || !lattice->carries_poisson()) return false;
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

}  // namespace tissue
