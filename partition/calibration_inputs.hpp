// What only calibration reads of the rank's share: made by the model builders with the layout, handed to the
// calibration methods, and dropped once the stiffness is final (12 bytes a molecule, 16 a connection with
// tetrahedra, that a solve never reads).
#pragma once
#include <vector>

namespace tissue {

struct CalibrationInputs {
  std::vector<double> youngs_modulus;   // local molecules, Pa
  std::vector<int> degree;              // local molecules: connections of each in the whole body
  // Local connections, tetrahedral topologies, meshes and random clouds only (empty otherwise): the volume of the
  // tetrahedra incident on each connection (Van Gelder's Eq. 5) and the sum over them of l_equiv = (6 sqrt2 V)^(1/3)
  // (Lloyd, Szekely & Harders 2007).
  std::vector<double> tetra_volume;
  std::vector<double> tetra_lloyd_sum;
};

}  // namespace tissue
