// Homogenized: springs assembled per cell so that every cell, on its own, has the elastic constants of the
// isotropic material with Young's modulus E and Poisson ratio 1/4 (the only isotropic one central springs give:
// Cauchy relation). Under a uniform strain a cell's springs then exert on its corners exactly the forces of the
// uniform stress on the corners' tributary faces, so the affine solution of a tension test with roller supports
// and a traction load is the lattice's equilibrium: E and nu = 1/4 are measured to round-off in the
// small-strain limit, for any n x n x n block (reference/calibration.md, "Exact on finite bodies").
//
// A connection's k = (number of cells it belongs to) x (its per-cell value), the cells counted from its ends'
// grid indices: an edge inside is in 4 cells, on a face 2, on a box edge 1; a face diagonal inside 2, on the
// surface 1; a body diagonal 1. E is the mean of the connection's two end molecules' moduli (exact for a
// homogeneous body; a heterogeneous one gets a per-connection blend, no per-cell average, which would need
// molecules a rank does not hold).
//
// Per cell (spacing h_x, h_y, h_z, volume V, mu = 2E/5 the shear modulus at nu = 1/4, so that
// C11 = 3 mu, C12 = C44 = mu), from C_ijkl = (1/V) sum over the cell's springs k L^2 n_i n_j n_k n_l:
//  - body diagonals (4, L_b^2 = h_x^2 + h_y^2 + h_z^2), only in topology body-diagonals:
//        k_b = t mu V L_b^2 / (4 max_{a<b} h_a^2 h_b^2), t = 1/2 (below); they give C_ab = 4 k_b h_a^2 h_b^2 / (L_b^2 V).
//  - face diagonals in the plane of axes a, b (4 per cell: 2 faces x 2), L^2 = h_a^2 + h_b^2: they make up
//    the rest of C_ab = mu:   k_ab = (mu - C_ab from body diagonals) V L^2 / (4 h_a^2 h_b^2).
//  - edges along a (4 per cell): the rest of C_aa = 3 mu:
//        k_a = (3 mu - sum_b 4 k_ab h_a^4 / (L_ab^2 V) - 4 k_b h_a^4 / (L_b^2 V)) V / (4 h_a^2).
// Cubic cells (h = a): face-diagonals gives E a / 10 per edge and E a / 5 per face diagonal; with t = 1 and no
// face diagonals one would get E a / 5 per edge and 3 E a / 10 per body diagonal (the reference's two exact
// sets). The body-diagonals topology has both diagonal kinds; any blend t of the two sets stays exact and
// isotropic (it keeps k1 = k2 + 8 k3 / 3 on the infinite lattice); t = 1/2 is chosen, the even blend: per cubic
// cell 3 E a / 20 per edge, E a / 10 per face diagonal, 3 E a / 20 per body diagonal.
// Unequal spacing: the same formulas make each rectangular cell exactly isotropic (so E and nu = 1/4 stay exact)
// as long as every edge k_a comes out positive, i.e. for face-diagonals h_a^2/h_b^2 + h_a^2/h_c^2 < 3 for every
// axis a (with h_x = h_y: 0.707 < h_z/h_x < 1.22; the Table 2 box, h_z/h_x = 0.86, is inside). Beyond that no
// isotropic cell of central springs of these directions exists: a negative edge k is set to 0 (the cell is then
// stiffer along that axis than the material; not exact) and rank 0 says so on stderr.
// Rectangular topology (edges only): isotropy is impossible (nu = 0); each cell gives k_a = E V / (4 h_a^2) to its
// edges, exact for the uniaxial modulus (C11 = E, C12 = 0). Tetrahedral (Kuhn) cells have one diagonal per
// face and are refused: no per-class split makes them isotropic.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"
#include "src/model/topology.hpp"

namespace tissue {

namespace {

struct CellSprings {
  double edge[3] = {0, 0, 0};  // along axis a
  double face[3] = {0, 0, 0};  // diagonal of the face normal to axis w
  double body = 0;
  bool clamped = false;
};

// Per-cell spring constants for E = 1 (they scale with E).
CellSprings cell_springs(const Vec3& h, const std::string& topology) {
  CellSprings s;
  const double V = h[0] * h[1] * h[2];
  const double h2[3] = {h[0] * h[0], h[1] * h[1], h[2] * h[2]};
  if (topology == "rectangular") {
    for (int a = 0; a < 3; ++a) s.edge[a] = V / (4.0 * h2[a]);
    return s;
  }
  const double mu = 0.4;
  const double Lb2 = h2[0] + h2[1] + h2[2];
  if (topology == "body-diagonals") {
    const double t = 0.5;
    const double most = std::max({h2[0] * h2[1], h2[0] * h2[2], h2[1] * h2[2]});
    s.body = t * mu * V * Lb2 / (4.0 * most);
  }
  for (int w = 0; w < 3; ++w) {
    const int a = (w + 1) % 3, b = (w + 2) % 3;
    const double from_body = 4.0 * s.body * h2[a] * h2[b] / (Lb2 * V);
    s.face[w] = (mu - from_body) * V * (h2[a] + h2[b]) / (4.0 * h2[a] * h2[b]);
  }
  for (int a = 0; a < 3; ++a) {
    double rest = 3.0 * mu - 4.0 * s.body * h2[a] * h2[a] / (Lb2 * V);
    for (int b = 0; b < 3; ++b)
      if (b != a) rest -= 4.0 * s.face[3 - a - b] * h2[a] * h2[a] / ((h2[a] + h2[b]) * V);
    if (rest < 0) rest = 0, s.clamped = true;
    s.edge[a] = rest * V / (4.0 * h2[a]);
  }
  return s;
}

}  // namespace

void calibrate_homogenized(const CalibrationContext& ctx, std::vector<double>& k) {
  const LocalModel& m = ctx.model;
  const Body& shape = m.shape;
  const std::string& topology = shape.topology;
  const TopologyStyle* lattice = find_topology(topology);
  if (!lattice || lattice->tetrahedra)
    throw InputError(ctx.scene.file, "calibration.method",
                     "homogenized needs a box lattice topology (rectangular, face-diagonals or body-diagonals), "
                     "not \"" + topology + "\"");
  const CellSprings cell = cell_springs(shape.h, topology);
  if (cell.clamped && m.rank == 0)
    std::fprintf(stderr, "tissue: homogenized: cells %g x %g x %g m are too far from cubic for an isotropic cell of "
                         "central springs; negative edge stiffness set to 0 (E and nu will not be exact)\n",
                 shape.h[0], shape.h[1], shape.h[2]);
  for (int c = 0; c < m.connections(); ++c) {
    const auto ia = shape.index(m.id[m.end_a[c]]), ib = shape.index(m.id[m.end_b[c]]);
    int cells = 1, differ[3], nd = 0;
    for (int d = 0; d < 3; ++d) {
      if (ia[d] != ib[d]) {
        differ[nd++] = d;
      } else {
        const long i = ia[d];
        cells *= (i >= 1 ? 1 : 0) + (i <= shape.n[d] - 2 ? 1 : 0);
      }
    }
    double per_cell = nd == 1 ? cell.edge[differ[0]] : nd == 2 ? cell.face[3 - differ[0] - differ[1]] : cell.body;
    const double E = 0.5 * (ctx.inputs.youngs_modulus[m.end_a[c]] + ctx.inputs.youngs_modulus[m.end_b[c]]);
    k[c] = cells * per_cell * E;
  }
}

TISSUE_CALIBRATION(homogenized, {"homogenized", calibrate_homogenized,
                                 "per-cell springs exact for an isotropic E, nu = 1/4 (Cauchy-Born)", nullptr,
                                 nullptr, CalibrationNeeds::lattice_cells});

}  // namespace tissue
