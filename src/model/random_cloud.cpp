#include "src/model/random_cloud.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "src/model/delaunay.hpp"
#include "src/model/random_draw.hpp"
#include "src/model/uniform_grid.hpp"

namespace tissue {

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

  // Interior molecules by dart throwing.
  const Vec3 L{(n[0] - 1) * h[0], (n[1] - 1) * h[1], (n[2] - 1) * h[2]};
  UniformGrid grid({0.0, 0.0, 0.0}, L, dmin);
  for (std::int64_t id = 0; id < static_cast<std::int64_t>(mesh.nodes.size()); ++id)
    insert_point(grid, mesh.nodes, id, dmin);
  const std::int64_t target = (n[0] - 2) * (n[1] - 2) * static_cast<std::int64_t>(n[2] - 2);
  std::int64_t placed = 0, tries = 0;
  while (placed < target) {
    if (++tries > 1000 * (target + 10))
      throw InputError(mesh.file, "", fmt::format("placed only {} of {} interior molecules", placed, target));
    Vec3 x;
    for (int d = 0; d < 3; ++d) x[d] = uniform(rng) * L[d];
    bool free = clear_of_points(grid, mesh.nodes, x, dmin);
    // Also keep dmin from the faces: a molecule nearly on a face makes flat tetrahedra there.
    for (int d = 0; d < 3; ++d) free = free && x[d] >= dmin && x[d] <= L[d] - dmin;
    if (!free) continue;
    mesh.nodes.push_back(x);
    insert_point(grid, mesh.nodes, static_cast<std::int64_t>(mesh.nodes.size()) - 1, dmin);
    ++placed;
  }

  const Delaunay3 dt = delaunay(mesh.nodes);
  mesh.tets = dt.tets;
  mesh.tet_region.assign(mesh.tets.size(), -1);

  // Faces: the hull triangles (opposite the infinite vertex) lying on each plane of the box.
  const char* names[6] = {"x-", "x+", "y-", "y+", "z-", "z+"};
  mesh.surfaces.resize(6);
  for (int f = 0; f < 6; ++f) mesh.surfaces[f].name = names[f];
  for (const auto& tri : dt.hull)
    for (int d = 0; d < 3; ++d)
      for (int side = 0; side < 2; ++side) {
        const double plane = side ? L[d] : 0.0;
        bool on = true;
        for (auto id : tri) on = on && mesh.nodes[id][d] == plane;
        if (on) mesh.surfaces[2 * d + side].triangles.push_back(tri);
      }
  for (auto& s : mesh.surfaces) std::sort(s.triangles.begin(), s.triangles.end());
  return mesh;
}

}  // namespace tissue
