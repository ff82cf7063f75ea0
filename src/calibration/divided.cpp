// Divided by a constant: the linear k over C. The paper tried values by hand (C = 3.75 on its Table 2 box)
// and found C must change with the object; the iterative method finds C by measurement.
#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"

namespace tissue {

void calibrate_divided(const CalibrationContext& ctx, std::vector<double>& k) {
  const double C = ctx.scene.calibration.divisor;
  for (int c = 0; c < ctx.model.connections(); ++c) k[c] = linear_stiffness(ctx, c) / C;
}

TISSUE_CALIBRATION(divided, {"divided", calibrate_divided, "the linear k divided by a constant C (calibration.divisor)",
                             nullptr, nullptr, CalibrationNeeds::any_topology, /*reads_divisor=*/true});

}  // namespace tissue
