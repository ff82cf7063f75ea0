// topology = "random": the paper's general case, molecules at random in a box joined by a Delaunay
// tetrahedralization (CGAL). Seeded (body.seed), so the same scene gives the same cloud on any rank count.
#pragma once
#include "src/model/unstructured.hpp"

namespace tissue {

// The box of spec (molecules, spacing) as a cloud of about the same number of molecules: the lattice's boundary
// molecules jittered within their face (up to 0.3 h; corners stay), so the hull is the box and faces x- .. z+
// stay planes, and (n_x - 2)(n_y - 2)(n_z - 2) interior molecules uniform at random, none closer than h_min / 2
// to another (dart throwing, so that no connection is much shorter than the spacing). Faces x- .. z+ are the
// hull's triangles on each plane.
TetMesh random_cloud(const BodySpec& spec);

}  // namespace tissue
