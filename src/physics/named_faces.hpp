// Faces of explicit topologies (meshes, random boxes; Body::faces): the tension test of Eq. 3, holds and loads
// on a named face. The box versions (force_model.cpp, measure.cpp) read faces from the lattice indices instead.
#pragma once
#include <cstdint>

#include "partition/local_model.hpp"
#include "src/physics/force_model.hpp"

namespace tissue {

// Eq. 3 on an explicit body: the load's face and a fixed face of the same body (on a random box, the one
// opposite), l0 = the distance between the two faces' centroids along the load, A = the body's volume / l0
// (exact for a prism between the two faces: on a box, its length and cross-section). Fills t; valid when found.
void named_tension_test(const Scene& scene, const Body& shape, TensionTest& t);

// The components `fix` holds at molecule g (on its named face): clamped all; roller the face-normal one, plus
// both in-plane ones at the face's anchor and one at its second anchor (NamedFace).
void hold_named(const NamedFace& face, const FixSpec& fix, std::int64_t g, std::uint8_t* held);

// The load's share on each owned molecule of its named face, added to out (3 * owned).
void add_named_face_load(const LoadSpec& load, const NamedFace& face, const LocalModel& model, double* out);

}  // namespace tissue
