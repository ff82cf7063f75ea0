// The tension test of Eq. 3 that the scene describes, when it describes one: the loaded named face and a fixed
// face of the same body (for faces named x- .. z+, the one opposite); a box's faces and a mesh's alike.
#pragma once
#include <cstdint>
#include <vector>

#include "src/model/body.hpp"
#include "src/model/scene.hpp"

namespace tissue {

// One loaded face with a fixed face. l0 = the distance between the two faces (along their normal when both are
// planes normal to one axis, else between their centroids along the load), A = the body's volume / l0 (exact for
// a prism between the two faces: on a box, its cross-section).
struct TensionTest {
  bool valid = false;
  int body = 0;  // the body the load is on
  int axis = 2, load_side = 0, fixed_side = 1;
  Vec3 direction{0, 0, -1};  // unit vector of the load
  double force = 0.0;        // N, total, the load's nominal force
  TimeHistory history;       // its factor in time (empty: 1), as the load's
  double force_at(double t) const { return force * history_factor(history, t); }  // N: applied at time t
  double rest_length = 0.0, cross_section = 0.0;
  int load_face = -1, fixed_face = -1;  // the two faces Eq. 3 reads: indices in Body::faces
  // measure()'s face membership of the owned molecules (src/measure/measure.cpp), found on its first call: a
  // history.csv row every step must not test faces molecule by molecule (lattice indices cost divisions).
  mutable std::vector<std::uint8_t> face_bits;
};
TensionTest tension_test(const Scene& scene, const Body& shape);

}  // namespace tissue
