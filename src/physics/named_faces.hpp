// Faces of explicit topologies (meshes, random boxes; Body::faces): holds and loads on a named face (the tension
// test of Eq. 3 on named faces: tension_test.cpp). The box versions (force_model.cpp, measure.cpp) read faces from
// the lattice indices instead.
#pragma once
#include <cstdint>

#include "partition/local_model.hpp"
#include "src/model/scene.hpp"

namespace tissue {

// The components `fix` holds at molecule g (on its named face): clamped all; roller the face-normal one, plus
// both in-plane ones at the face's anchor and one at its second anchor (NamedFace).
void hold_named(const NamedFace& face, const FixSpec& fix, std::int64_t g, std::uint8_t* held);

// The load's share on each owned molecule of its named face, added to out (3 * owned).
void add_named_face_load(const LoadSpec& load, const NamedFace& face, const LocalModel& model, double* out);

}  // namespace tissue
