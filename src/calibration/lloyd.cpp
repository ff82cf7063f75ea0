// Lloyd, Szekely & Harders 2007 ("Identification of spring parameters for deformable object simulation", IEEE
// TVCG 13(5)): each tetrahedron gives each of its 6 edges k = (2 sqrt2 / 25) E l_equiv, with l_equiv =
// (6 sqrt2 V)^(1/3) the edge length of the regular tetrahedron of the same volume V; a connection's k is the sum
// over the tetrahedra incident on it (CalibrationInputs::tetra_lloyd_sum holds the sum of l_equiv, made at
// distribution). Exact, for nu = 1/4, on a regular tetrahedron only; the Kuhn mesh is anisotropic. E per
// connection is the mean of its two end molecules' moduli. Tetrahedral topology only.
#include <cmath>

#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"

namespace tissue {

void require_tetrahedra(const CalibrationContext& ctx, const char* method);  // tetrahedral.cpp

void calibrate_lloyd(const CalibrationContext& ctx, std::vector<double>& k) {
  require_tetrahedra(ctx, "lloyd");
  const LocalModel& m = ctx.model;
  const double factor = 2.0 * std::sqrt(2.0) / 25.0;
  for (int c = 0; c < m.connections(); ++c) {
    const double E = 0.5 * (ctx.inputs.youngs_modulus[m.end_a[c]] + ctx.inputs.youngs_modulus[m.end_b[c]]);
    k[c] = factor * E * ctx.inputs.tetra_lloyd_sum[c];
  }
}

TISSUE_CALIBRATION(lloyd, {"lloyd", calibrate_lloyd, "Lloyd et al. 2007: k = sum (2 sqrt2 / 25) E l_equiv per tetrahedron",
                           nullptr, nullptr, CalibrationNeeds::tetrahedra});

}  // namespace tissue
