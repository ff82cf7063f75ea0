#include "src/model/body.hpp"

#include <algorithm>
#include <initializer_list>

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

namespace {

// One body of the scene, numbered from `first`: geometry, topology, per-molecule material and mass.
Body build_one(const BodySpec& spec, std::int64_t first) {
  Body b;
  b.n = spec.molecules;
  b.h = spec.spacing;
  b.offset = spec.offset;
  b.topology = spec.topology;
  b.radius = spec.radius ? *spec.radius : 0.5 * std::min({spec.spacing[0], spec.spacing[1], spec.spacing[2]});
  find_topology(spec.topology)->build(b);  // the scene reader has checked the name
  std::sort(b.connections.begin(), b.connections.end(), [](const Connection& x, const Connection& y) {
    return x.a != y.a ? x.a < y.a : x.b < y.b;
  });

  // Material per molecule: the body's, then each region in turn (the last region holding a molecule wins).
  // A connection across a region's boundary joins two materials: the calibration methods see both ends' E
  // (linear uses their mean).
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
  if (first != 0) {
    for (auto& c : b.connections) c.a += first, c.b += first;
    for (auto& t : b.tetrahedra)
      for (auto& v : t) v += first;
    b.first = first;
  }
  return b;
}

}  // namespace

Body build_body(const Scene& scene) {
  const std::vector<BodySpec> single{scene.body};
  const std::vector<BodySpec>& specs = scene.bodies.empty() ? single : scene.bodies;
  Body all = build_one(specs[0], 0);
  all.parts.push_back(all);
  all.parts.back().first = 0;
  for (std::size_t i = 1; i < specs.size(); ++i) {
    Body b = build_one(specs[i], all.molecules());
    all.parts.push_back(static_cast<const BoxGeometry&>(b));
    all.connections.insert(all.connections.end(), b.connections.begin(), b.connections.end());
    all.tetrahedra.insert(all.tetrahedra.end(), b.tetrahedra.begin(), b.tetrahedra.end());
    all.youngs_modulus.insert(all.youngs_modulus.end(), b.youngs_modulus.begin(), b.youngs_modulus.end());
    all.mass.insert(all.mass.end(), b.mass.begin(), b.mass.end());
  }
  return all;
}

}  // namespace tissue
