// shape = "mesh" with topology = "random": molecules at random inside a mesh's volume, joined by a Delaunay
// tetrahedralization carved to the volume (issue #9, "sampled in ... a mesh volume").
#pragma once
#include <string>

#include "src/model/unstructured.hpp"

namespace tissue {

// From the tetrahedral mesh `in` (read_gmsh): its boundary nodes and the nodes of its physical surfaces stay (in
// node order, so every named face keeps its molecules and triangles), and spec.interior_molecules points follow,
// uniform by volume over the tetrahedra (seeded by spec.seed), by dart throwing at least dmin = cbrt(V / count) / 2
// from each other, from the kept nodes and from the boundary (as the random box keeps them apart). The Delaunay
// tetrahedra of all points are kept when their centroid and their 6 edge midpoints lie in `in` (so no connection
// crosses a concave notch of the volume), each in the region of the tetrahedron of `in` holding its centroid.
// Throws InputError naming scene_file and key.interior_molecules when the points do not fit or the carving leaves
// molecules without connections or the body in pieces.
TetMesh random_in_mesh(const TetMesh& in, const BodySpec& spec, const std::string& scene_file, const std::string& key);

}  // namespace tissue
