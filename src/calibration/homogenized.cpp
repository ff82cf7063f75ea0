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
// Unequal spacing: the same formulas make each rectangular cell exactly isotropic as long as every edge k_a comes
// out positive, i.e. for face-diagonals h_a^2/h_b^2 + h_a^2/h_c^2 < 3 for every axis a (with h_x = h_y:
// 0.707 < h_z/h_x < 1.22; the Table 2 box, h_z/h_x = 0.86, is inside). Beyond that no isotropic cell of central
// springs of these directions exists: the diagonals are scaled down and the cell term
// (src/physics/terms/cell_elasticity.cpp) carries the shear they leave out, so E and nu stay exact for cells from
// 1:4 to 4:1 and beyond (src/model/cell_law.hpp).
// Any Poisson ratio: the springs carry lambda = mu = s = min(mu, 3K/5) of the target (E_s = 2.5 s instead of E
// below) and the cell term the rest (docs/poisson.md).
// Rectangular topology (edges only): isotropy is impossible (nu = 0); each cell gives k_a = E V / (4 h_a^2) to its
// edges, exact for the uniaxial modulus (C11 = E, C12 = 0). Tetrahedral (Kuhn) cells have one diagonal per
// face and are refused: no per-class split makes them isotropic.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"
#include "src/model/cell_law.hpp"
#include "src/model/topology.hpp"

namespace tissue {

void calibrate_homogenized(const CalibrationContext& ctx, std::vector<double>& k) {
  const LocalModel& m = ctx.model;
  const Body& shape = m.shape;
  const std::string& topology = shape.topology;
  if (shape.unstructured()) {
    // A mesh or a cloud: the per-tetrahedron term (src/physics/terms/tetrahedron_elasticity.cpp) carries the whole
    // target, exact for every affine state; springs on an irregular graph are not isotropic, so they carry nothing.
    std::fill(k.begin(), k.end(), 0.0);
    return;
  }
  const TopologyStyle* lattice = find_topology(topology);
  if (!lattice || lattice->tetrahedra)
    throw InputError(ctx.scene.file, "calibration.method",
                     "homogenized needs a box lattice topology (rectangular, face-diagonals or body-diagonals), "
                     "not \"" + topology + "\"");
  const CellSprings cell = cell_springs(shape.h, lattice->cells);
  // The springs' modulus E_s per molecule: E itself unless the molecule has a Poisson ratio (cell_law.hpp).
  const std::vector<BodySpec> specs = ctx.scene.bodies.empty() ? std::vector<BodySpec>{ctx.scene.body} : ctx.scene.bodies;
  std::vector<double> spring_modulus;
  if (m.connections() > 0) {
    const int b = m.body[m.end_a[0]];
    const BodySpec& spec = specs[b];
    bool any_nu = spec.poisson_ratio.has_value() || spec.has_fibres();
    for (const auto& r : spec.regions) any_nu = any_nu || r.poisson_ratio.has_value();
    if (any_nu) {
      spring_modulus = ctx.inputs.youngs_modulus;
      for (int i = 0; i < m.local; ++i)
        if (m.body[i] == b) {
          const MoleculeMaterial mat = molecule_material(spec, shape, m.id[i]);
          // With fibres the springs carry the matrix part of the TI target (cell_law.hpp).
          spring_modulus[i] = cell_moduli(ctx.inputs.youngs_modulus[i], mat.poisson_ratio, mat.fibres).spring_modulus;
        }
    }
  }
  const std::vector<double>& Es = spring_modulus.empty() ? ctx.inputs.youngs_modulus : spring_modulus;
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
    const double E = 0.5 * (Es[m.end_a[c]] + Es[m.end_b[c]]);
    k[c] = cells * per_cell * E;
  }
}

TISSUE_CALIBRATION(homogenized, {"homogenized", calibrate_homogenized,
                                 "per-cell springs (and a cell term for nu != 1/4 or flat cells) exact for an isotropic E, nu", nullptr,
                                 nullptr, CalibrationNeeds::lattice_cells, /*reads_divisor=*/false,
                                 /*honours_poisson=*/true});

}  // namespace tissue
