// The linear case, Eq. 4: k = E A / l0 for each connection, with A l0 the volume of the body the connection
// stands for. An edge along axis a stands for the tributary prism around it (A = w_u w_v, the widths of its
// molecules across the edge, halved on the boundary; l0 = h_a): on the rectangular topology a tension test then
// measures E exactly. A face diagonal stands for its share of the face slab (h_u h_v w_w over the diagonals of
// that face), a body diagonal for its share of the cell: the paper's reading, which counts the volume once per
// connection class and so makes diagonal topologies too stiff (its Table 2: +274%).
#include <cmath>

#include "partition/local_model.hpp"
#include "src/model/topology.hpp"
#include "src/calibration/calibration.hpp"

namespace tissue {

double linear_stiffness(const CalibrationContext& ctx, int c) {
  const LocalModel& m = ctx.model;
  const BoxGeometry& s = m.shape.part(m.id[m.end_a[c]]);  // the body the connection lies in
  if (s.unstructured()) return linear_stiffness_tetrahedral(ctx, c);  // linear_tetrahedral.cpp
  auto ia = s.index(m.id[m.end_a[c]]), ib = s.index(m.id[m.end_b[c]]);
  int differ[3], nd = 0;
  for (int d = 0; d < 3; ++d)
    if (ia[d] != ib[d]) differ[nd++] = d;
  const bool tetrahedral = find_topology(s.topology)->tetrahedra;  // every cell split into tetrahedra
  double volume = 0.0;
  if (nd == 1) {  // edge along differ[0]
    int a = differ[0], u = (a + 1) % 3, v = (a + 2) % 3;
    volume = s.width(ia[u], u) * s.width(ia[v], v) * s.h[a];
  } else if (nd == 2) {  // face diagonal, normal to the axis that does not change
    int w = 3 - differ[0] - differ[1];
    volume = s.h[differ[0]] * s.h[differ[1]] * s.width(ia[w], w) / (tetrahedral ? 1.0 : 2.0);
  } else {  // body diagonal
    volume = s.h[0] * s.h[1] * s.h[2] / (tetrahedral ? 1.0 : 4.0);
  }
  const double E = 0.5 * (ctx.inputs.youngs_modulus[m.end_a[c]] + ctx.inputs.youngs_modulus[m.end_b[c]]);
  const double l0 = m.l0(c);
  return E * volume / (l0 * l0);
}

void calibrate_linear(const CalibrationContext& ctx, std::vector<double>& k) {
  for (int c = 0; c < ctx.model.connections(); ++c) k[c] = linear_stiffness(ctx, c);
}

TISSUE_CALIBRATION(linear, {"linear", calibrate_linear, "Eq. 4, k = E A / l0 with the volume each connection stands for"});

}  // namespace tissue
