// Manual: one k per connection class (edge, face, body), so a run can be compared with another code on the very
// same discrete model (the LAMMPS peer uses k = 1 on every spring).
#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"

namespace tissue {

void calibrate_manual(const CalibrationContext& ctx, std::vector<double>& k) {
  const auto& table = ctx.scene.calibration.stiffness;
  for (int c = 0; c < ctx.model.connections(); ++c) {
    auto it = table.find(class_name(ctx.model.connection_class[c]));
    k[c] = it == table.end() ? 0.0 : it->second;  // the scene reader requires every class the topology uses
  }
}

TISSUE_CALIBRATION(manual, {"manual", calibrate_manual, "k given per connection class (calibration.stiffness)",
                            nullptr, nullptr, CalibrationNeeds::any_topology, false, false, /*reads_stiffness=*/true});

}  // namespace tissue
