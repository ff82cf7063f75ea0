#include "src/physics/named_faces.hpp"

namespace tissue {

void hold_named(const NamedFace& face, const FixSpec& fix, std::int64_t g, std::uint8_t* held) {
  if (!face.contains(g)) return;
  if (fix.mode == FixSpec::Mode::clamped || face.axis < 0) {  // the scene check refuses rollers on faces without an axis
    held[0] = held[1] = held[2] = 1;
    return;
  }
  held[face.axis] = 1;
  if (g == face.anchor) held[(face.axis + 1) % 3] = held[(face.axis + 2) % 3] = 1;
  if (g == face.anchor2) held[face.anchor2_component] = 1;
}

void add_named_face_load(const LoadSpec& load, const NamedFace& face, const LocalModel& model, double* out) {
  const double count = face.count();
  for (int i = 0; i < model.owned; ++i) {
    if (model.body[i] != load.body || !face.contains(model.id[i])) continue;
    // traction: each molecule's share is its tributary area on the face; equal: the same share for all.
    const double share = load.distribution == LoadSpec::Distribution::equal ? 1.0 / count : face.area_of(model.id[i]) / face.total_area;
    for (int d = 0; d < 3; ++d) out[3 * i + d] += share * load.force[d];
  }
}

}  // namespace tissue
