#include "src/model/body.hpp"

#include <algorithm>
#include <initializer_list>
#include <limits>

#include "src/model/material.hpp"

namespace tissue {

const char* class_name(ConnectionClass c) {
  switch (c) {
    case ConnectionClass::edge: return "edge";
    case ConnectionClass::face: return "face";
    case ConnectionClass::body: return "body";
  }
  return "?";
}

std::ptrdiff_t NamedFace::find(std::int64_t id) const {
  auto it = std::lower_bound(molecules.begin(), molecules.end(), id);
  return it != molecules.end() && *it == id ? it - molecules.begin() : -1;
}

BoxGeometry body_geometry(const BodySpec& spec, std::int64_t first) {
  BoxGeometry b;
  b.n = spec.molecules;
  b.h = spec.spacing;
  b.offset = spec.offset;
  b.topology = spec.topology;
  b.radius = spec.radius ? *spec.radius : 0.5 * std::min({spec.spacing[0], spec.spacing[1], spec.spacing[2]});
  b.first = first;
  return b;
}

// Material per molecule: the body's, then each region in turn (the last region holding a molecule wins). A
// connection across a region's boundary joins two materials: the calibration methods see both ends' E.
MoleculeMaterial molecule_material(const BodySpec& spec, const BoxGeometry& box, std::int64_t id) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const FibreSpec* body_fibres = spec.fibres ? &*spec.fibres : nullptr;
  MoleculeMaterial m{spec.youngs_modulus, spec.density, spec.poisson_ratio.value_or(nan), body_fibres};
  if (spec.regions.empty()) return m;
  const Vec3 x = box.rest_position(id);
  for (const auto& r : spec.regions) {
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      double xa = x[a] - box.offset[a], tol = 1e-9 * box.h[a];
      inside = inside && xa >= r.lo[a] - tol && xa <= r.hi[a] + tol;
    }
    if (inside) m = {r.youngs_modulus, r.density, r.poisson_ratio.value_or(nan), r.fibres ? &*r.fibres : body_fibres};
  }
  return m;
}

Body scene_shape(const Scene& scene) {
  const std::vector<BodySpec> specs = scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
  Body all;
  std::int64_t first = 0;
  for (const auto& spec : specs) {
    all.parts.push_back(body_geometry(spec, first));
    first += all.parts.back().molecules();
  }
  static_cast<BoxGeometry&>(all) = all.parts[0];
  return all;
}

}  // namespace tissue
