#include "src/model/body.hpp"

#include <algorithm>
#include <initializer_list>
#include <limits>

#include "src/model/material.hpp"
#include "src/model/mesh_cloud.hpp"
#include "src/model/random_cloud.hpp"
#include "src/model/topology.hpp"
#include "src/model/unstructured.hpp"

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

namespace {

// The geometry of one body of the scene, numbered from `first`.
BoxGeometry geometry_of(const BodySpec& spec, std::int64_t first) {
  BoxGeometry b;
  b.n = spec.molecules;
  b.h = spec.spacing;
  b.offset = spec.offset;
  b.topology = spec.topology;
  b.radius = spec.radius ? *spec.radius : 0.5 * std::min({spec.spacing[0], spec.spacing[1], spec.spacing[2]});
  b.first = first;
  return b;
}

// One body of the scene, numbered from `first`: geometry, topology, per-molecule material and mass.
Body build_one(const BodySpec& spec, std::int64_t first) {
  Body b;
  static_cast<BoxGeometry&>(b) = geometry_of(spec, 0);
  find_topology(spec.topology)->build(b);  // the scene reader has checked the name
  std::sort(b.connections.begin(), b.connections.end(), [](const Connection& x, const Connection& y) {
    return x.a != y.a ? x.a < y.a : x.b < y.b;
  });
  const std::int64_t n = b.molecules();
  b.youngs_modulus.resize(n);
  b.mass.resize(n);
  for (std::int64_t m = 0; m < n; ++m) {
    const MoleculeMaterial mat = molecule_material(spec, b, m);
    b.youngs_modulus[m] = mat.youngs_modulus;
    b.mass[m] = mat.density * b.volume(m);
  }
  if (first != 0) {
    for (auto& c : b.connections) c.a += first, c.b += first;
    for (auto& t : b.tetrahedra)
      for (auto& v : t) v += first;
    b.first = first;
  }
  return b;
}

// Explicit topologies (a mesh file, a random cloud) go through a tetrahedral mesh; boxes through their stencil.
Body build_any(const Scene& scene, const MeshReader& read_mesh, const BodySpec& spec, std::size_t index,
               std::size_t count, std::int64_t first) {
  const std::string key = count > 1 ? "body[" + std::to_string(index) + "]" : "body";
  if (spec.shape == "mesh" && !read_mesh) throw std::logic_error("build_body: a mesh body and no mesh reader");
  if (spec.shape == "mesh" && spec.topology == "random")
    return build_unstructured(spec, random_in_mesh(read_mesh(spec), spec, scene.file, key), first, scene.file, key);
  if (spec.shape == "mesh") return build_unstructured(spec, read_mesh(spec), first, scene.file, key);
  if (spec.topology == "random") return build_unstructured(spec, random_cloud(spec), first, scene.file, key);
  return build_one(spec, first);
}

std::vector<BodySpec> specs_of(const Scene& scene) {
  return scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
}

}  // namespace

// Material per molecule: the body's, then each region in turn (the last region holding a molecule wins). A
// connection across a region's boundary joins two materials: the calibration methods see both ends' E.
MoleculeMaterial molecule_material(const BodySpec& spec, const BoxGeometry& box, std::int64_t id) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  MoleculeMaterial m{spec.youngs_modulus, spec.density, spec.poisson_ratio.value_or(nan)};
  if (spec.regions.empty()) return m;
  const Vec3 x = box.rest_position(id);
  for (const auto& r : spec.regions) {
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      double xa = x[a] - box.offset[a], tol = 1e-9 * box.h[a];
      inside = inside && xa >= r.lo[a] - tol && xa <= r.hi[a] + tol;
    }
    if (inside) m = {r.youngs_modulus, r.density, r.poisson_ratio.value_or(nan)};
  }
  return m;
}

Body scene_shape(const Scene& scene) {
  const std::vector<BodySpec> specs = specs_of(scene);
  Body all;
  std::int64_t first = 0;
  for (const auto& spec : specs) {
    all.parts.push_back(geometry_of(spec, first));
    first += all.parts.back().molecules();
  }
  static_cast<BoxGeometry&>(all) = all.parts[0];
  return all;
}

Body build_body(const Scene& scene, const MeshReader& read_mesh) {
  const std::vector<BodySpec> specs = specs_of(scene);
  Body all = build_any(scene, read_mesh, specs[0], 0, specs.size(), 0);
  all.parts.push_back(all);
  all.parts.back().first = 0;
  for (std::size_t i = 1; i < specs.size(); ++i) {
    Body b = build_any(scene, read_mesh, specs[i], i, specs.size(), all.molecules());
    all.parts.push_back(static_cast<const BoxGeometry&>(b));
    all.connections.insert(all.connections.end(), b.connections.begin(), b.connections.end());
    all.tetrahedra.insert(all.tetrahedra.end(), b.tetrahedra.begin(), b.tetrahedra.end());
    all.youngs_modulus.insert(all.youngs_modulus.end(), b.youngs_modulus.begin(), b.youngs_modulus.end());
    all.mass.insert(all.mass.end(), b.mass.begin(), b.mass.end());
    if (!all.points.empty() || !b.points.empty()) {  // explicit positions for all once one body has them
      for (std::int64_t m = static_cast<std::int64_t>(all.points.size()); m < b.first; ++m)
        all.points.push_back(all.part(m).rest_position(m));
      for (std::int64_t m = b.first; m < b.first + b.molecules(); ++m)
        all.points.push_back(b.points.empty() ? b.rest_position(m) : b.points[m - b.first]);
    }
    for (auto& f : b.faces) f.body = static_cast<int>(i), all.faces.push_back(f);
  }
  check_face_names(scene, all);
  return all;
}

}  // namespace tissue
