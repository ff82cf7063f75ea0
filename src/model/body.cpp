#include "src/model/body.hpp"

#include <algorithm>

#include "src/model/material.hpp"
#include "src/model/topology.hpp"

namespace tissue {

const char* class_name(ConnectionClass c) {
  switch (c) {
    case ConnectionClass::edge: return "edge";
    case ConnectionClass::face: return "face";
    case ConnectionClass::body: return "body";
  }
  return "?";
}

Body build_body(const Scene& scene) {
  const BodySpec& spec = scene.body;
  Body b;
  b.n = spec.molecules;
  b.h = spec.spacing;
  b.offset = spec.offset;
  b.topology = spec.topology;
  find_topology(spec.topology)->build(b);  // the scene reader has checked the name
  std::sort(b.connections.begin(), b.connections.end(), [](const Connection& x, const Connection& y) {
    return x.a != y.a ? x.a < y.a : x.b < y.b;
  });

  // Material per molecule: the body's, then each region in turn (the last region holding a molecule wins).
  const std::int64_t n = b.molecules();
  b.youngs_modulus.assign(n, spec.youngs_modulus);
  std::vector<double> density(n, spec.density);
  for (const auto& r : spec.regions)
    for (std::int64_t m = 0; m < n; ++m) {
      Vec3 x = b.rest_position(m);
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        double xa = x[a] - b.offset[a], tol = 1e-9 * b.h[a];
        inside = inside && xa >= r.lo[a] - tol && xa <= r.hi[a] + tol;
      }
      if (inside) b.youngs_modulus[m] = r.youngs_modulus, density[m] = r.density;
    }
  b.mass.resize(n);
  for (std::int64_t m = 0; m < n; ++m) b.mass[m] = density[m] * b.volume(m);
  return b;
}

}  // namespace tissue
