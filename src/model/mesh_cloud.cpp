#include "src/model/mesh_cloud.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "src/model/delaunay.hpp"
#include "src/model/random_draw.hpp"
#include "src/model/tet_locator.hpp"
#include "src/model/uniform_grid.hpp"

namespace tissue {
namespace {

using Triangle = std::array<std::int64_t, 3>;

Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// Squared distance from p to the triangle abc (Ericson, Real-Time Collision Detection, 5.1.5: the closest point
// by the Voronoi region of p among the triangle's corners, edges and face).
double distance2_to_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  auto at = [&](double v, double w) {  // the point a + v ab + w ac
    Vec3 q;
    for (int d = 0; d < 3; ++d) q[d] = a[d] + v * ab[d] + w * ac[d] - p[d];
    return dot(q, q);
  };
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return dot(ap, ap);
  const Vec3 bp = sub(p, b);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return dot(bp, bp);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return at(d1 / (d1 - d3), 0);
  const Vec3 cp = sub(p, c);
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return dot(cp, cp);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return at(0, d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return at(1 - w, w);
  }
  const double denom = 1 / (va + vb + vc);
  return at(vb * denom, vc * denom);
}

// The triangles that bound the mesh: tetrahedron faces that only one tetrahedron has.
std::vector<Triangle> boundary_of(const TetMesh& m) {
  std::vector<Triangle> faces;
  faces.reserve(4 * m.tets.size());
  for (const auto& t : m.tets)
    for (int skip = 0; skip < 4; ++skip) {
      Triangle f;
      int k = 0;
      for (int v = 0; v < 4; ++v)
        if (v != skip) f[k++] = t[v];
      std::sort(f.begin(), f.end());
      faces.push_back(f);
    }
  std::sort(faces.begin(), faces.end());
  std::vector<Triangle> once;
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i;
    while (j < faces.size() && faces[j] == faces[i]) ++j;
    if (j - i == 1) once.push_back(faces[i]);
    i = j;
  }
  return once;
}

// A uniform point in the tetrahedron abcd from three uniform draws (Rocchini and Cignoni 2000: the unit cube
// folded into the corner simplex, which keeps the density uniform).
Vec3 point_in_tet(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d, double s, double t, double u) {
  if (s + t > 1) s = 1 - s, t = 1 - t;
  if (t + u > 1) {
    const double tmp = u;
    u = 1 - s - t, t = 1 - tmp;
  } else if (s + t + u > 1) {
    const double tmp = u;
    u = s + t + u - 1, s = 1 - t - tmp;
  }
  const double w = 1 - s - t - u;
  Vec3 x;
  for (int k = 0; k < 3; ++k) x[k] = w * a[k] + s * b[k] + t * c[k] + u * d[k];
  return x;
}

std::int64_t find_root(std::vector<std::int64_t>& parent, std::int64_t i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

}  // namespace

TetMesh random_in_mesh(const TetMesh& in, const BodySpec& spec, const std::string& scene_file, const std::string& key) {
  const std::string count_key = key + ".interior_molecules";
  TetMesh out;
  out.file = in.file;
  out.region_names = in.region_names;

  // Kept nodes: the boundary's and the physical surfaces' (an inner surface, too, keeps its molecules).
  const std::vector<Triangle> boundary = boundary_of(in);
  std::vector<char> keep(in.nodes.size(), 0);
  for (const auto& f : boundary)
    for (auto v : f) keep[v] = 1;
  for (const auto& s : in.surfaces)
    for (const auto& f : s.triangles)
      for (auto v : f) keep[v] = 1;
  std::vector<std::int64_t> new_id(in.nodes.size(), -1);
  for (std::size_t i = 0; i < in.nodes.size(); ++i)
    if (keep[i]) new_id[i] = static_cast<std::int64_t>(out.nodes.size()), out.nodes.push_back(in.nodes[i]);

  // Interior points: a tetrahedron drawn by volume, a point uniform in it; kept if dmin clear of the others and
  // of the boundary (a point nearly on the boundary makes flat tetrahedra there).
  std::vector<double> cumulative(in.tets.size());
  double volume = 0;
  for (std::size_t t = 0; t < in.tets.size(); ++t) {
    const auto& T = in.tets[t];
    volume += signed_volume(in.nodes[T[0]], in.nodes[T[1]], in.nodes[T[2]], in.nodes[T[3]]);
    cumulative[t] = volume;
  }
  const std::int64_t count = spec.interior_molecules;
  const double dmin = 0.5 * std::cbrt(volume / static_cast<double>(count));
  Vec3 lo = in.nodes[0], hi = in.nodes[0];
  for (const auto& p : in.nodes)
    for (int d = 0; d < 3; ++d) lo[d] = std::min(lo[d], p[d]), hi[d] = std::max(hi[d], p[d]);
  UniformGrid points(lo, hi, dmin), walls(lo, hi, dmin);
  for (std::int64_t i = 0; i < static_cast<std::int64_t>(out.nodes.size()); ++i) insert_point(points, out.nodes, i, dmin);
  for (std::size_t f = 0; f < boundary.size(); ++f) {
    Vec3 a = in.nodes[boundary[f][0]], b = a;
    for (auto v : boundary[f])
      for (int d = 0; d < 3; ++d) a[d] = std::min(a[d], in.nodes[v][d] - dmin), b[d] = std::max(b[d], in.nodes[v][d] + dmin);
    walls.insert(static_cast<std::int64_t>(f), a, b);
  }
  std::mt19937_64 rng(static_cast<std::uint64_t>(spec.seed));
  std::int64_t placed = 0, tries = 0;
  while (placed < count) {
    if (++tries > 1000 * (count + 10))
      throw InputError(scene_file, count_key,
                       fmt::format("placed only {} of {} interior molecules in {} at least {:.3g} m from each other "
                                   "and from the surface (the volume is too thin for so few: ask for more)",
                                   placed, count, in.file, dmin));
    const double r = uniform(rng) * volume;
    const std::size_t t = std::min<std::size_t>(std::upper_bound(cumulative.begin(), cumulative.end(), r) -
                                                cumulative.begin(), in.tets.size() - 1);
    const auto& T = in.tets[t];
    const double s = uniform(rng), v = uniform(rng), w = uniform(rng);
    const Vec3 x = point_in_tet(in.nodes[T[0]], in.nodes[T[1]], in.nodes[T[2]], in.nodes[T[3]], s, v, w);
    bool free = clear_of_points(points, out.nodes, x, dmin);
    for (auto f : walls.candidates(x)) {
      if (!free) break;
      const auto& B = boundary[f];
      free = distance2_to_triangle(x, in.nodes[B[0]], in.nodes[B[1]], in.nodes[B[2]]) >= dmin * dmin;
    }
    if (!free) continue;
    out.nodes.push_back(x);
    insert_point(points, out.nodes, static_cast<std::int64_t>(out.nodes.size()) - 1, dmin);
    ++placed;
  }

  // Delaunay, carved: a tetrahedron stays when its centroid and its edges' midpoints lie in the mesh.
  const Delaunay3 dt = delaunay(out.nodes);
  const TetLocator locator(in);
  for (const auto& T : dt.tets) {
    Vec3 centroid{};
    for (auto v : T)
      for (int d = 0; d < 3; ++d) centroid[d] += 0.25 * out.nodes[v][d];
    const std::int64_t home = locator.locate(centroid);
    bool inside = home >= 0;
    for (int a = 0; inside && a < 4; ++a)
      for (int b = a + 1; inside && b < 4; ++b) {
        Vec3 mid;
        for (int d = 0; d < 3; ++d) mid[d] = 0.5 * (out.nodes[T[a]][d] + out.nodes[T[b]][d]);
        inside = locator.locate(mid) >= 0;
      }
    if (!inside) continue;
    out.tets.push_back(T);
    out.tet_region.push_back(in.tet_region.empty() ? -1 : in.tet_region[home]);
  }

  // Every molecule joined, and all in one piece.
  const std::int64_t n = static_cast<std::int64_t>(out.nodes.size());
  std::vector<std::int64_t> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  std::vector<char> used(n, 0);
  for (const auto& T : out.tets)
    for (int v = 0; v < 4; ++v) {
      used[T[v]] = 1;
      parent[find_root(parent, T[v])] = find_root(parent, T[0]);
    }
  const std::int64_t unused = std::count(used.begin(), used.end(), 0);
  if (unused > 0) {
    const std::int64_t i = std::find(used.begin(), used.end(), 0) - used.begin();
    throw InputError(scene_file, count_key,
                     fmt::format("carving the Delaunay tetrahedra to {} left {} of {} molecules without connections "
                                 "(the first at [{:.6g}, {:.6g}, {:.6g}]); ask for more interior molecules",
                                 in.file, unused, n, out.nodes[i][0], out.nodes[i][1], out.nodes[i][2]));
  }
  std::int64_t pieces = 0;
  for (std::int64_t i = 0; i < n; ++i) pieces += find_root(parent, i) == i;
  if (pieces > 1)
    throw InputError(scene_file, count_key,
                     fmt::format("carving the Delaunay tetrahedra to {} left the body in {} pieces; ask for more "
                                 "interior molecules", in.file, pieces));

  // The named faces: the mesh's own triangles on the kept nodes (their areas are the surfaces').
  for (const auto& s : in.surfaces) {
    TetMesh::Surface f{s.name, {}};
    for (const auto& tri : s.triangles) f.triangles.push_back({new_id[tri[0]], new_id[tri[1]], new_id[tri[2]]});
    out.surfaces.push_back(std::move(f));
  }
  return out;
}

}  // namespace tissue
