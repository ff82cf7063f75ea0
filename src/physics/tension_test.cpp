#include "src/physics/tension_test.hpp"

#include <cmath>

namespace tissue {

namespace {

// Eq. 3 on an explicit body: the load's face and a fixed face of the same body (on a random box, the one
// opposite), l0 = the distance between the two faces' centroids along the load, A = the body's volume / l0
// (exact for a prism between the two faces: on a box, its length and cross-section). Fills t; valid when found.
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

}  // namespace

TensionTest tension_test(const Scene& scene, const Body& shape) {
  TensionTest t;
  if (scene.loads.size() != 1) return t;
  if (scene.loads[0].period > 0) return t;  // a cyclic load measures no modulus
  if (shape.body(scene.loads[0].body).unstructured()) {  // named faces: named_tension_test above
    named_tension_test(scene, shape, t);
    return t;
  }
  int axis, side;
  parse_face(scene.loads[0].face, axis, side);
  t.body = scene.loads[0].body;
  for (const auto& fix : scene.fixes) {
    int fa, fs;
    parse_face(fix.face, fa, fs);
    if (fix.body == t.body && fa == axis && fs != side) t.valid = true;
  }
  if (!t.valid) return t;
  const BoxGeometry& g = shape.body(t.body);
  const Vec3& F = scene.loads[0].force;
  t.force = std::sqrt(F[0] * F[0] + F[1] * F[1] + F[2] * F[2]);
  for (int d = 0; d < 3; ++d) t.direction[d] = F[d] / t.force;
  t.axis = axis, t.load_side = side, t.fixed_side = 1 - side;
  t.rest_length = g.length(axis);
  t.cross_section = g.length((axis + 1) % 3) * g.length((axis + 2) % 3);
  return t;
}

}  // namespace tissue
