#include "src/model/random_cloud.hpp"

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <unordered_map>

namespace tissue {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using VertexBase = CGAL::Triangulation_vertex_base_with_info_3<std::int64_t, Kernel>;
using Tds = CGAL::Triangulation_data_structure_3<VertexBase>;
using Delaunay = CGAL::Delaunay_triangulation_3<Kernel, Tds>;

// Uniform in [0, 1) from 53 random bits: the same sequence with any standard library.
double uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

}  // namespace

TetMesh random_cloud(const BodySpec& spec) {
  const auto& n = spec.molecules;
  const Vec3& h = spec.spacing;
  std::mt19937_64 rng(static_cast<std::uint64_t>(spec.seed));
  TetMesh mesh;
  mesh.file = fmt::format("random box (seed {})", spec.seed);
  const double hmin = std::min({h[0], h[1], h[2]}), dmin = 0.5 * hmin;

  // Boundary molecules: the lattice's, jittered along the axes in which they are interior.
  for (long k = 0; k < n[2]; ++k)
    for (long j = 0; j < n[1]; ++j)
      for (long i = 0; i < n[0]; ++i) {
        const long ijk[3] = {i, j, k};
        bool boundary = false;
        for (int d = 0; d < 3; ++d) boundary = boundary || ijk[d] == 0 || ijk[d] == n[d] - 1;
        if (!boundary) continue;
        Vec3 x;
        for (int d = 0; d < 3; ++d) {
          x[d] = ijk[d] * h[d];
          if (ijk[d] > 0 && ijk[d] < n[d] - 1) x[d] += 0.6 * (uniform(rng) - 0.5) * h[d];
        }
        mesh.nodes.push_back(x);
      }

  // Interior molecules by dart throwing on a hash grid of cell size dmin.
  const Vec3 L{(n[0] - 1) * h[0], (n[1] - 1) * h[1], (n[2] - 1) * h[2]};
  std::array<long, 3> cells;
  for (int d = 0; d < 3; ++d) cells[d] = std::max(1L, static_cast<long>(L[d] / dmin));
  auto cell_of = [&](const Vec3& x, int d) {
    return std::min(cells[d] - 1, std::max(0L, static_cast<long>(x[d] / L[d] * cells[d])));
  };
  std::unordered_map<std::int64_t, std::vector<std::int64_t>> grid;
  auto key = [&](long a, long b, long c) { return a + cells[0] * (b + static_cast<std::int64_t>(cells[1]) * c); };
  auto insert = [&](std::int64_t id) {
    const Vec3& x = mesh.nodes[id];
    grid[key(cell_of(x, 0), cell_of(x, 1), cell_of(x, 2))].push_back(id);
  };
  for (std::int64_t id = 0; id < static_cast<std::int64_t>(mesh.nodes.size()); ++id) insert(id);
  const std::int64_t target = (n[0] - 2) * (n[1] - 2) * static_cast<std::int64_t>(n[2] - 2);
  std::int64_t placed = 0, tries = 0;
  while (placed < target) {
    if (++tries > 1000 * (target + 10))
      throw InputError(mesh.file, "", fmt::format("placed only {} of {} interior molecules", placed, target));
    Vec3 x;
    for (int d = 0; d < 3; ++d) x[d] = uniform(rng) * L[d];
    bool free = true;
    const long c[3] = {cell_of(x, 0), cell_of(x, 1), cell_of(x, 2)};
    for (long a = c[0] - 1; free && a <= c[0] + 1; ++a)
      for (long b = c[1] - 1; free && b <= c[1] + 1; ++b)
        for (long e = c[2] - 1; free && e <= c[2] + 1; ++e) {
          if (a < 0 || b < 0 || e < 0 || a >= cells[0] || b >= cells[1] || e >= cells[2]) continue;
          auto it = grid.find(key(a, b, e));
          if (it == grid.end()) continue;
          for (auto id : it->second) {
            double d2 = 0;
            for (int d = 0; d < 3; ++d) d2 += (mesh.nodes[id][d] - x[d]) * (mesh.nodes[id][d] - x[d]);
            if (d2 < dmin * dmin) { free = false; break; }
          }
        }
    // Also keep dmin from the faces: a molecule nearly on a face makes flat tetrahedra there.
    for (int d = 0; d < 3; ++d) free = free && x[d] >= dmin && x[d] <= L[d] - dmin;
    if (!free) continue;
    mesh.nodes.push_back(x);
    insert(static_cast<std::int64_t>(mesh.nodes.size()) - 1);
    ++placed;
  }

  // Delaunay tetrahedralization; vertex info = molecule index.
  std::vector<std::pair<Kernel::Point_3, std::int64_t>> points;
  points.reserve(mesh.nodes.size());
  for (std::int64_t id = 0; id < static_cast<std::int64_t>(mesh.nodes.size()); ++id)
    points.push_back({Kernel::Point_3(mesh.nodes[id][0], mesh.nodes[id][1], mesh.nodes[id][2]), id});
  Delaunay dt(points.begin(), points.end());
  for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
    std::array<std::int64_t, 4> t;
    for (int v = 0; v < 4; ++v) t[v] = c->vertex(v)->info();
    if (signed_volume(mesh.nodes[t[0]], mesh.nodes[t[1]], mesh.nodes[t[2]], mesh.nodes[t[3]]) < 0) std::swap(t[2], t[3]);
    mesh.tets.push_back(t);
  }
  // Sorted, so the tetrahedra (and so every sum over them) come in an order of ids, not of CGAL's memory.
  std::sort(mesh.tets.begin(), mesh.tets.end());
  mesh.tet_region.assign(mesh.tets.size(), -1);

  // Faces: the hull triangles (opposite the infinite vertex) lying on each plane of the box.
  const char* names[6] = {"x-", "x+", "y-", "y+", "z-", "z+"};
  mesh.surfaces.resize(6);
  for (int f = 0; f < 6; ++f) mesh.surfaces[f].name = names[f];
  for (auto c = dt.all_cells_begin(); c != dt.all_cells_end(); ++c) {
    if (!dt.is_infinite(c)) continue;
    std::array<std::int64_t, 3> tri;
    int m = 0;
    for (int v = 0; v < 4; ++v)
      if (!dt.is_infinite(c->vertex(v))) tri[m++] = c->vertex(v)->info();
    for (int d = 0; d < 3; ++d)
      for (int side = 0; side < 2; ++side) {
        const double plane = side ? L[d] : 0.0;
        bool on = true;
        for (auto id : tri) on = on && mesh.nodes[id][d] == plane;
        if (on) mesh.surfaces[2 * d + side].triangles.push_back(tri);
      }
  }
  for (auto& s : mesh.surfaces) std::sort(s.triangles.begin(), s.triangles.end());
  return mesh;
}

}  // namespace tissue
