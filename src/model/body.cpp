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
  b.total_volume = b.length(0) * b.length(1) * b.length(2);
  return b;
}

std::vector<NamedFace> lattice_faces(const BoxGeometry& box, int b) {
  std::vector<NamedFace> faces;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      NamedFace f;
      f.body = b;
      f.name = std::string(1, static_cast<char>('x' + axis)) + (side ? "+" : "-");
      f.axis = axis, f.side = side, f.lattice = true, f.box = box;
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      f.plane = side ? box.length(axis) : 0.0;
      f.total_area = box.length(u) * box.length(v);
      f.centroid = box.offset;
      f.centroid[axis] += f.plane, f.centroid[u] += 0.5 * box.length(u), f.centroid[v] += 0.5 * box.length(v);
      // Roller anchors: the face's corner with the lowest in-plane indices (both in-plane components), and the
      // corner next to it along u (component v: stops the rotation about the normal). Two roller faces on one
      // axis take corners on the same edge; a uniform lateral contraction meets no resistance from these.
      std::array<long, 3> corner{};
      corner[axis] = side ? box.n[axis] - 1 : 0;
      f.anchor = box.id(corner[0], corner[1], corner[2]);
      corner[u] = box.n[u] - 1;
      f.anchor2 = box.id(corner[0], corner[1], corner[2]);
      f.anchor2_component = v;
      faces.push_back(std::move(f));
    }
  return faces;
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
    if (!spec.unstructured())  // explicit topologies' faces come with their molecules (partition/explicit_model)
      for (auto& f : lattice_faces(all.parts.back(), static_cast<int>(all.parts.size()) - 1))
        all.faces.push_back(std::move(f));
    first += all.parts.back().molecules();
  }
  static_cast<BoxGeometry&>(all) = all.parts[0];
  return all;
}

}  // namespace tissue
