// The tension test of Eq. 3 that the scene describes, when it describes one: on a box, the loaded face and the
// fixed face opposite (lattice indices); on an explicit topology (mesh, random box), the two named faces.
#pragma once
#include <string>

#include "src/model/body.hpp"
#include "src/model/scene.hpp"

namespace tissue {

// One loaded face with a fixed face opposite. l0 = distance between the two planes of molecules, A = the
// cross-section normal to the load axis.
struct TensionTest {
  bool valid = false;
  int body = 0;  // the body the load is on
  int axis = 2, load_side = 0, fixed_side = 1;
  Vec3 direction{0, 0, -1};  // unit vector of the load
  double force = 0.0;        // N, total
  double rest_length = 0.0, cross_section = 0.0;
  std::string load_face, fixed_face;  // explicit topologies (named faces): the two faces Eq. 3 reads
};
TensionTest tension_test(const Scene& scene, const Body& shape);

}  // namespace tissue
