#include "src/physics/tension_test.hpp"

#include <cmath>

namespace tissue {

TensionTest tension_test(const Scene& scene, const Body& shape) {
  TensionTest t;
  if (scene.loads.size() != 1) return t;
  const LoadSpec& load = scene.loads[0];
  if (load.period > 0) return t;  // a cyclic load measures no modulus
  t.body = load.body;             // the summary's target modulus is the loaded body's, even without a test
  t.history = load.history;
  const NamedFace* lf = shape.named_face(load.body, load.face);
  if (!lf) return t;
  for (const auto& fix : scene.fixes) {
    if (fix.body != load.body || fix.face == load.face) continue;
    const NamedFace* ff = shape.named_face(fix.body, fix.face);
    if (!ff) continue;
    // Faces named x- .. z+ (a box's, a random box's) pair with the one opposite only.
    if (lf->side >= 0 && !(ff->side >= 0 && ff->axis == lf->axis && ff->side != lf->side)) continue;
    const Vec3& F = load.force;
    t.force = std::sqrt(F[0] * F[0] + F[1] * F[1] + F[2] * F[2]);
    for (int d = 0; d < 3; ++d) t.direction[d] = F[d] / t.force;
    if (lf->axis >= 0 && lf->axis == ff->axis) {  // two planes normal to one axis: their distance along it
      t.axis = lf->axis;
      t.rest_length = std::fabs(lf->plane - ff->plane);
      t.load_side = lf->plane > ff->plane ? 1 : 0;
    } else {  // curved or tilted surfaces (a mesh's): the centroids' distance along the load
      double along = 0;
      for (int d = 0; d < 3; ++d) along += (lf->centroid[d] - ff->centroid[d]) * t.direction[d];
      t.axis = 0;
      for (int d = 1; d < 3; ++d)
        if (std::fabs(t.direction[d]) > std::fabs(t.direction[t.axis])) t.axis = d;
      t.rest_length = std::fabs(along);
      t.load_side = lf->centroid[t.axis] > ff->centroid[t.axis] ? 1 : 0;
    }
    if (t.rest_length == 0) continue;
    t.valid = true;
    t.fixed_side = 1 - t.load_side;
    t.load_face = static_cast<int>(lf - shape.faces.data());
    t.fixed_face = static_cast<int>(ff - shape.faces.data());
    t.cross_section = shape.body(load.body).total_volume / t.rest_length;
    return t;
  }
  return t;
}

}  // namespace tissue
