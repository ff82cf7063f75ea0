// Tetrahedral regions, Eq. 5 (Van Gelder 1998, "Approximate simulation of elastic membranes by triangulated
// spring meshes", extended by him to 3D): k_c = E sum_e vol(T_e) / |c|^2, the sum over the tetrahedra T_e incident
// on connection c (CalibrationInputs::tetra_volume, summed at distribution). E per connection is the mean of its two
// end molecules' moduli. Only the tetrahedral topology has tetrahedra: any other is refused.
//
// On the structured Kuhn mesh (6 tetrahedra per cube) the result is anisotropic: a cell edge touching the cell's
// (0,0,0) or (1,1,1) corner lies in 2 of the cell's tetrahedra, the others in 1, and the main diagonal in all 6.
#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"
#include "src/model/topology.hpp"

namespace tissue {

void require_tetrahedra(const CalibrationContext& ctx, const char* method) {
  const TopologyStyle* lattice = find_topology(ctx.model.shape.topology);  // nullptr: a mesh or random cloud
  if ((lattice && !lattice->tetrahedra) ||
      ctx.inputs.tetra_volume.size() != static_cast<std::size_t>(ctx.model.connections()))
    throw InputError(ctx.scene.file, "calibration.method",
                     std::string(method) + " needs tetrahedra (topology tetrahedral or random, or a mesh; it sums over the tetrahedra incident "
                                           "on each connection), not \"" + ctx.model.shape.topology + "\"");
}

void calibrate_tetrahedral(const CalibrationContext& ctx, std::vector<double>& k) {
  require_tetrahedra(ctx, "tetrahedral");
  const LocalModel& m = ctx.model;
  for (int c = 0; c < m.connections(); ++c) {
    const double E = 0.5 * (ctx.inputs.youngs_modulus[m.end_a[c]] + ctx.inputs.youngs_modulus[m.end_b[c]]);
    const double l = m.l0(c);
    k[c] = E * ctx.inputs.tetra_volume[c] / (l * l);
  }
}

TISSUE_CALIBRATION(tetrahedral, {"tetrahedral", calibrate_tetrahedral,
                                 "Eq. 5 (Van Gelder): k = E sum vol(T_e) / |c|^2; tetrahedral topology", nullptr,
                                 nullptr, CalibrationNeeds::tetrahedra});

}  // namespace tissue
