// Holds and loads on a named face (Body::faces: a box's lattice planes, a mesh's physical surfaces, a random
// box's x- .. z+), one path for every topology (Eq. 3 on the same faces: tension_test.cpp).
#pragma once
#include <cstdint>

#include "partition/local_model.hpp"
#include "src/model/scene.hpp"

namespace tissue {

// The components `fix` holds at molecule g (on its named face): clamped all; roller the face-normal one, plus
// both in-plane ones at the face's anchor and one at its second anchor (NamedFace). g is a molecule of the
// face's body.
void hold_named(const NamedFace& face, const FixSpec& fix, std::int64_t g, std::uint8_t* held);

// The load's share on each owned molecule of its named face, added to out (3 * owned).
void add_named_face_load(const LoadSpec& load, const NamedFace& face, const LocalModel& model, double* out);

}  // namespace tissue
