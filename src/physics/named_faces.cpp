#include "src/physics/named_faces.hpp"

#include <cmath>

namespace tissue {

void named_tension_test(const Scene& scene, const Body& shape, TensionTest& t) {
  const LoadSpec& load = scene.loads[0];
  const NamedFace* lf = shape.named_face(load.body, load.face);
  if (!lf) return;
  int la, ls;
  const bool lattice_names = parse_face(load.face, la, ls);  // a random box: the fixed face must be opposite
  for (const auto& fix : scene.fixes) {
    if (fix.body != load.body || fix.face == load.face) continue;
    int fa, fs;
    if (lattice_names && !(parse_face(fix.face, fa, fs) && fa == la && fs != ls)) continue;
    const NamedFace* ff = shape.named_face(fix.body, fix.face);
    if (!ff) continue;
    const Vec3& F = load.force;
    t.force = std::sqrt(F[0] * F[0] + F[1] * F[1] + F[2] * F[2]);
    for (int d = 0; d < 3; ++d) t.direction[d] = F[d] / t.force;
    double along = 0;
    for (int d = 0; d < 3; ++d) along += (lf->centroid[d] - ff->centroid[d]) * t.direction[d];
    if (std::fabs(along) == 0) continue;
    t.valid = true;
    t.body = load.body;
    t.axis = 0;
    for (int d = 1; d < 3; ++d)
      if (std::fabs(t.direction[d]) > std::fabs(t.direction[t.axis])) t.axis = d;
    t.load_side = lf->centroid[t.axis] > ff->centroid[t.axis] ? 1 : 0;
    t.fixed_side = 1 - t.load_side;
    t.load_face = load.face, t.fixed_face = fix.face;
    t.rest_length = std::fabs(along);
    t.cross_section = shape.body(load.body).total_volume / t.rest_length;
    return;
  }
}

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
  const double count = static_cast<double>(face.molecules.size());
  for (int i = 0; i < model.owned; ++i) {
    if (model.body[i] != load.body) continue;
    const auto k = face.find(model.id[i]);
    if (k < 0) continue;
    // traction: each molecule's share is its tributary area on the face; equal: the same share for all.
    const double share = load.distribution == "equal" ? 1.0 / count : face.area[k] / face.total_area;
    for (int d = 0; d < 3; ++d) out[3 * i + d] += share * load.force[d];
  }
}

}  // namespace tissue
