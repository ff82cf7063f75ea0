#include "src/model/unstructured.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace tissue {

double signed_volume(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& p3) {
  double e[3][3];
  const Vec3* p[3] = {&p1, &p2, &p3};
  for (int v = 0; v < 3; ++v)
    for (int d = 0; d < 3; ++d) e[v][d] = (*p[v])[d] - p0[d];
  return (e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) - e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
          e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0])) / 6.0;
}

namespace {

std::string names_of(const std::vector<std::string>& names) {
  if (names.empty()) return "none";
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "\"" : ", \"") + n + "\"";
  return s;
}

// A face from its triangles: per-molecule tributary area, centroid, and, when it is a plane normal to an axis,
// that axis and the roller anchors.
NamedFace make_face(const TetMesh::Surface& s, const std::vector<Vec3>& x, std::int64_t first) {
  NamedFace f;
  f.name = s.name;
  std::vector<std::pair<std::int64_t, double>> shares;
  double extent = 0;
  for (const auto& p : x)
    for (int d = 0; d < 3; ++d) extent = std::max(extent, std::fabs(p[d]));
  bool plane[3] = {true, true, true};
  Vec3 sum{};
  for (const auto& t : s.triangles) {
    const Vec3 &a = x[t[0]], &b = x[t[1]], &c = x[t[2]];
    Vec3 n{(b[1] - a[1]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[1] - a[1]),
           (b[2] - a[2]) * (c[0] - a[0]) - (b[0] - a[0]) * (c[2] - a[2]),
           (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])};
    const double area = 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int d = 0; d < 3; ++d) {
      sum[d] += area * (a[d] + b[d] + c[d]) / 3.0;
      // A plane normal to axis d: every corner on the first corner's coordinate (to round-off of the extent).
      const double x0 = x[s.triangles[0][0]][d], tol = 1e-9 * std::max(extent, 1e-300);
      plane[d] = plane[d] && std::fabs(a[d] - x0) <= tol && std::fabs(b[d] - x0) <= tol && std::fabs(c[d] - x0) <= tol;
    }
    f.total_area += area;
    for (int v = 0; v < 3; ++v) shares.push_back({t[v] + first, area / 3.0});
  }
  std::sort(shares.begin(), shares.end());
  for (const auto& [id, a] : shares) {
    if (f.molecules.empty() || f.molecules.back() != id) f.molecules.push_back(id), f.area.push_back(0.0);
    f.area.back() += a;
  }
  for (int d = 0; d < 3; ++d) f.centroid[d] = f.total_area > 0 ? sum[d] / f.total_area : 0.0;
  for (int d = 0; d < 3; ++d)
    if (plane[d] && !s.triangles.empty()) f.axis = d;
  if (f.axis >= 0) {
    f.plane = f.centroid[f.axis];
    int axis, side;  // named x- .. z+ (a random box's faces): the side of the box it lies on
    if (parse_face(f.name, axis, side) && axis == f.axis) f.side = side;
    // Anchors by id and distance only: the same on every rank count.
    f.anchor = f.molecules.front();
    const Vec3& p = x[f.anchor - first];
    const int u = (f.axis + 1) % 3, v = (f.axis + 2) % 3;
    // anchor2 holds one in-plane component c against rotation about the normal. Best on a line through the anchor
    // along the other in-plane axis (q_c = p_c), as a box's anchors are: then a uniform in-plane stretch (a free
    // lateral contraction) moves no held component, and the face is a roller indeed. Else the farthest molecule.
    double best = -1, extent = 0;
    for (auto id : f.molecules)
      for (int d : {u, v}) extent = std::max(extent, std::fabs(x[id - first][d] - p[d]));
    const double tol = 1e-9 * extent;
    for (auto id : f.molecules) {
      const Vec3& q = x[id - first];
      for (int c : {v, u}) {
        const int o = c == v ? u : v;
        if (std::fabs(q[c] - p[c]) <= tol && std::fabs(q[o] - p[o]) > best)
          best = std::fabs(q[o] - p[o]), f.anchor2 = id, f.anchor2_component = c;
      }
    }
    if (!(best > 0.1 * extent)) {
      best = -1;
      for (auto id : f.molecules) {
        const Vec3& q = x[id - first];
        double d2 = 0;
        for (int d = 0; d < 3; ++d) d2 += (q[d] - p[d]) * (q[d] - p[d]);
        if (d2 > best) best = d2, f.anchor2 = id;
      }
      const Vec3& q = x[f.anchor2 - first];
      f.anchor2_component = std::fabs(q[u] - p[u]) >= std::fabs(q[v] - p[v]) ? v : u;
    }
  }
  return f;
}

}  // namespace

MeshMolecules mesh_molecules(const BodySpec& spec, const TetMesh& mesh, std::int64_t first,
                             const std::string& scene_file, const std::string& key) {
  MeshMolecules b;
  const std::int64_t n = static_cast<std::int64_t>(mesh.nodes.size());
  b.points.resize(n);
  for (std::int64_t i = 0; i < n; ++i)
    for (int d = 0; d < 3; ++d) b.points[i][d] = mesh.nodes[i][d] + spec.offset[d];

  // Regions: the scene's names against the mesh's physical volumes.
  std::vector<int> spec_of_region(mesh.region_names.size(), -1);  // mesh region -> last scene region naming it
  for (std::size_t r = 0; r < spec.regions.size(); ++r) {
    auto it = std::find(mesh.region_names.begin(), mesh.region_names.end(), spec.regions[r].name);
    if (it == mesh.region_names.end())
      throw InputError(scene_file, fmt::format("{}.region[{}].name", key, r),
                       fmt::format("no physical volume \"{}\" in {} (it has: {})", spec.regions[r].name, mesh.file,
                                   names_of(mesh.region_names)));
    spec_of_region[it - mesh.region_names.begin()] = static_cast<int>(r);
  }

  b.mass.assign(n, 0.0);
  std::vector<int> region_of(n, -1);  // the last scene region among the molecule's tetrahedra
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
    const auto& T = mesh.tets[t];
    const double vol = signed_volume(b.points[T[0]], b.points[T[1]], b.points[T[2]], b.points[T[3]]);
    if (!(vol > 0))  // readers refuse these with the element named; this guards the other sources
      throw InputError(mesh.file, "", fmt::format("tetrahedron {} is inverted or flat (volume {:.3e})", t, vol));
    const int r = mesh.tet_region.empty() || mesh.tet_region[t] < 0 ? -1 : spec_of_region[mesh.tet_region[t]];
    const double rho = r >= 0 ? spec.regions[r].density : spec.density;
    b.total_volume += vol;
    for (int v = 0; v < 4; ++v) {
      b.mass[T[v]] += 0.25 * rho * vol;
      region_of[T[v]] = std::max(region_of[T[v]], r);
    }
  }
  b.youngs_modulus.resize(n);
  for (std::int64_t i = 0; i < n; ++i) {
    if (b.mass[i] <= 0)
      throw InputError(mesh.file, "", fmt::format("node {} belongs to no tetrahedron", i));
    b.youngs_modulus[i] = region_of[i] >= 0 ? spec.regions[region_of[i]].youngs_modulus : spec.youngs_modulus;
  }
  for (const auto& s : mesh.surfaces) b.faces.push_back(make_face(s, b.points, first));
  return b;
}

double tetrahedron_volume(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& p3) {
  const Vec3* p[4] = {&p0, &p1, &p2, &p3};
  double e[3][3];
  for (int v = 0; v < 3; ++v)
    for (int d = 0; d < 3; ++d) e[v][d] = (*p[v + 1])[d] - p0[d];
  return std::fabs(e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
                   e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                   e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0])) / 6.0;
}

Body build_unstructured(const BodySpec& spec, const TetMesh& mesh, std::int64_t first, const std::string& scene_file,
                        const std::string& key) {
  Body b;
  const std::int64_t n = static_cast<std::int64_t>(mesh.nodes.size());
  b.count = n;
  b.topology = spec.topology;  // "mesh" (its own tetrahedra) or "random" (in a box or in a mesh volume)
  b.offset = spec.offset;
  b.first = first;
  MeshMolecules molecules = mesh_molecules(spec, mesh, first, scene_file, key);
  b.points = std::move(molecules.points);
  b.mass = std::move(molecules.mass);
  b.youngs_modulus = std::move(molecules.youngs_modulus);
  b.total_volume = molecules.total_volume;
  b.faces = std::move(molecules.faces);

  std::vector<Connection> edges;
  edges.reserve(6 * mesh.tets.size());
  for (const auto& T : mesh.tets) {
    Tetrahedron g;
    for (int v = 0; v < 4; ++v) {
      g[v] = T[v] + first;
      for (int w = v + 1; w < 4; ++w)
        edges.push_back({std::min(T[v], T[w]) + first, std::max(T[v], T[w]) + first, ConnectionClass::edge});
    }
    b.tetrahedra.push_back(g);
  }
  std::sort(edges.begin(), edges.end(),
            [](const Connection& x, const Connection& y) { return x.a != y.a ? x.a < y.a : x.b < y.b; });
  edges.erase(std::unique(edges.begin(), edges.end(),
                          [](const Connection& x, const Connection& y) { return x.a == y.a && x.b == y.b; }),
              edges.end());
  b.connections = std::move(edges);

  // Nominal size: the mean connection length stands for the spacing (default contact radius: half of it), and
  // n for a cube of the same count (what iteration caps scale with).
  double sum = 0;
  for (const auto& c : b.connections) sum += edge_length(b.points[c.a - first], b.points[c.b - first]);
  set_nominal_size(b, spec, sum, b.connections.size());
  return b;
}

double edge_length(const Vec3& a, const Vec3& b) {
  double l2 = 0;
  for (int d = 0; d < 3; ++d) l2 += std::pow(b[d] - a[d], 2);
  return std::sqrt(l2);
}

void set_nominal_size(BoxGeometry& b, const BodySpec& spec, double length_sum, std::int64_t connections) {
  const double mean = length_sum / static_cast<double>(std::max<std::int64_t>(connections, 1));
  b.h = {mean, mean, mean};
  const long side = std::max(2L, std::lround(std::cbrt(static_cast<double>(b.count))));
  b.n = {side, side, side};
  b.radius = spec.radius ? *spec.radius : 0.5 * mean;
}

void check_face_names(const Scene& scene, const Body& body) {
  auto check = [&](const std::string& what, std::size_t i, int bi, const std::string& face) {
    if (body.named_face(bi, face)) return;  // a box's names are checked by the scene reader
    std::vector<std::string> names;
    for (const auto& f : body.faces)
      if (f.body == bi) names.push_back(f.name);
    const BodySpec& spec = scene.bodies.empty() ? scene.body : scene.bodies[bi];
    throw InputError(scene.file, fmt::format("{}[{}].face", what, i),
                     fmt::format("no physical surface \"{}\" in {} (it has: {})", face,
                                 spec.shape == BodySpec::Shape::mesh ? spec.file : std::string("the random box"), names_of(names)));
  };
  for (std::size_t i = 0; i < scene.fixes.size(); ++i) {
    const FixSpec& fix = scene.fixes[i];
    check("fix", i, fix.body, fix.face);
    const NamedFace* face = body.named_face(fix.body, fix.face);
    if (face && fix.mode == FixSpec::Mode::roller && face->axis < 0)
      throw InputError(scene.file, fmt::format("fix[{}].mode", i),
                       fmt::format("a roller needs a plane face normal to x, y or z; \"{}\" is not one (use "
                                   "\"clamped\")", fix.face));
  }
  for (std::size_t i = 0; i < scene.loads.size(); ++i) check("load", i, scene.loads[i].body, scene.loads[i].face);
}

}  // namespace tissue
