#include "src/model/delaunay.hpp"

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <algorithm>

#include "src/model/unstructured.hpp"

namespace tissue {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using VertexBase = CGAL::Triangulation_vertex_base_with_info_3<std::int64_t, Kernel>;
using Tds = CGAL::Triangulation_data_structure_3<VertexBase>;
using Triangulation = CGAL::Delaunay_triangulation_3<Kernel, Tds>;

}  // namespace

Delaunay3 delaunay(const std::vector<Vec3>& nodes) {
  std::vector<std::pair<Kernel::Point_3, std::int64_t>> points;
  points.reserve(nodes.size());
  for (std::int64_t id = 0; id < static_cast<std::int64_t>(nodes.size()); ++id)
    points.push_back({Kernel::Point_3(nodes[id][0], nodes[id][1], nodes[id][2]), id});
  Triangulation dt(points.begin(), points.end());
  Delaunay3 out;
  for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
    std::array<std::int64_t, 4> t;
    for (int v = 0; v < 4; ++v) t[v] = c->vertex(v)->info();
    if (signed_volume(nodes[t[0]], nodes[t[1]], nodes[t[2]], nodes[t[3]]) < 0) std::swap(t[2], t[3]);
    out.tets.push_back(t);
  }
  std::sort(out.tets.begin(), out.tets.end());
  // The hull: each infinite cell's finite face.
  for (auto c = dt.all_cells_begin(); c != dt.all_cells_end(); ++c) {
    if (!dt.is_infinite(c)) continue;
    std::array<std::int64_t, 3> tri;
    int m = 0;
    for (int v = 0; v < 4; ++v)
      if (!dt.is_infinite(c->vertex(v))) tri[m++] = c->vertex(v)->info();
    out.hull.push_back(tri);
  }
  std::sort(out.hull.begin(), out.hull.end());
  return out;
}

}  // namespace tissue
