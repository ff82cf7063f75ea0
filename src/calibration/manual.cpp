// Manual: one k per connection class (edge, face, body), so a run can be compared with another code on the very
// same discrete model (the LAMMPS peer uses k = 1 on every spring).
#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"

namespace tissue {

void calibrate_manual(const CalibrationContext& ctx, std::vector<double>& k) {
  const auto& table = ctx.scene.calibration.stiffness;
  double by_class[3];  // looked up once per class, not by name per connection
  for (int cls = 0; cls < 3; ++cls) {
    auto it = table.find(class_name(static_cast<ConnectionClass>(cls)));
    by_class[cls] = it == table.end() ? 0.0 : it->second;  // the scene reader requires every class the topology uses
  }
  for (int c = 0; c < ctx.model.connections(); ++c) k[c] = by_class[static_cast<int>(ctx.model.connection_class[c])];
}

TISSUE_CALIBRATION(manual, {"manual", calibrate_manual, "k given per connection class (calibration.stiffness)",
                            nullptr, nullptr, CalibrationNeeds::any_topology, false, false, /*reads_stiffness=*/true});

}  // namespace tissue
