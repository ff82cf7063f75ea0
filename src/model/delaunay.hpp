// The Delaunay tetrahedralization of a point set (CGAL 5.5, exact predicates), for the random topologies.
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "src/model/scene.hpp"

namespace tissue {

struct Delaunay3 {
  // Positively oriented; the list is sorted (by corner ids), so every sum over tetrahedra comes in an order of
  // ids, not of CGAL's memory.
  std::vector<std::array<std::int64_t, 4>> tets;
  std::vector<std::array<std::int64_t, 3>> hull;  // the convex hull's triangles
};

// Point i is vertex i.
Delaunay3 delaunay(const std::vector<Vec3>& points);

}  // namespace tissue
